"""Reading CAN frames: the raw log (BLF) and the vectorised decoder of its frames per the DBC."""
