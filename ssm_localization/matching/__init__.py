"""Spectral scan matching (paper section II): scan geometry, descriptors, affinity, eigenvector, RANSAC."""
