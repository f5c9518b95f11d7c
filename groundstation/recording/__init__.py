"""Sortie recording to MCAP (Foxglove's well-known JSON schemas) and reading it back."""
