"""Database: schema, migrations and persistence of campaigns and observations."""
