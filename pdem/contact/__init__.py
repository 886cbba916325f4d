"""pdem.contact."""
