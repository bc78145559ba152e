"""Simulated instruments that speak the real wire protocols over real transports."""
