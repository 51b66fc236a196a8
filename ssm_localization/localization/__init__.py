"""
Global localization on an indexed map (paper section IV).

Localizer, refinement, verification.
"""
