"""Figures people would rather see than read (PNG via matplotlib, imported lazily)."""
from __future__ import annotations


def _pyplot():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt
