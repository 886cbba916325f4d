"""pdem.model."""
