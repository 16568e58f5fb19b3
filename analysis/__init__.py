"""haulprofile analysis: logs to gradient, mass, representative cycles, wheel loads and simulation."""
