"""Analysis: pure computation of the seed-000 method and report rendering (no bus, no database)."""
