//! The simulator (SITL): building, vehicles, sensors, and simulated shield and autopilot endpoints. Not built yet: see the SITL issue (#3).
