"""Register-level I2C sensor drivers (datasheet register maps) and the source that polls them."""
