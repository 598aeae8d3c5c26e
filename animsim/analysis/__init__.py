"""Analyses that read runs: energy, stability, check, compare, references."""
