"""ssm_localization: single-scan global localization with spectral scan matching (Park & Park)."""
__version__ = '0.1.0'

from .matching.matcher import MatcherConfig, MatchResult, match_scans  # noqa: E402

__all__ = ['MatcherConfig', 'MatchResult', 'match_scans', '__version__']
