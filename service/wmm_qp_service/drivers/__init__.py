"""Drivers of real robots: processes that speak the daemon's protocol for a robot's own interface."""
