"""haulprofile in-truck logger: CAN, I2C sensors and GPS into crash-safe MCAP files."""
