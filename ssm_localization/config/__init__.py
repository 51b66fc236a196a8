"""Configuration dataclasses and YAML params files (imports nothing from the rest of the package)."""
