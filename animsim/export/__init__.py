"""Exporters: files, plots and animations made from recorded frames."""
