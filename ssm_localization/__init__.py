"""ssm_localization: single-scan global localization with spectral scan matching (Park & Park)."""
__version__ = '0.1.0'
