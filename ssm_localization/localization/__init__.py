"""Global localization on an indexed map (paper section IV): localizer, refinement, verification."""
