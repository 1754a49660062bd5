"""Devices: adapters turning an instrument's native stream into the frames the engine consumes."""
