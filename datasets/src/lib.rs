//! Generators of MD-like data.
