"""Peregrine ground station: simulator, sortie runner and (later) the operator's web app."""

__version__ = "0.1.0"
