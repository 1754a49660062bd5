"""Stand: CAN protocol, stand controller client and the simulated gyrocompass on a roll stand."""
