"""Spectral scan matching (paper section II): scan geometry, features and descriptors, the
affinity matrix and its leading eigenvector, RANSAC and ICP (``match_scans``)."""
