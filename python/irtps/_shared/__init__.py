"""Helpers that every layer shares: argument checks, paths, atomic outputs, resources, bounded JSON, records."""
