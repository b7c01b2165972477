"""Visualisation: evaluation plots and offscreen rendering of interactions."""
