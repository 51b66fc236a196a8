"""
Spectral scan matching (paper section II).

Scan geometry, features and descriptors, the affinity matrix and its leading eigenvector, RANSAC
and ICP (``match_scans``).
"""
