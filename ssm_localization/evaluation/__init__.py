"""Offline evaluation: replay against ground truth, RESULTS.csv, figures."""
