"""Acquisition: runs rolling-stand campaigns over CAN into the database."""
