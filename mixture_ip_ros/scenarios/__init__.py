"""Demonstration sets: generated scenarios that mirror the thesis's experiments."""
