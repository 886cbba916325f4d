"""Closed-form engineering checks that need no simulation (limit equilibrium of rock wedges)."""
