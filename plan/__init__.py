"""The campaign plan: one typed model of a plan file, parsed once, used by every layer."""
