"""A reconstruction's figures and web page."""
