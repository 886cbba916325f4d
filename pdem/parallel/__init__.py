"""pdem.parallel."""
