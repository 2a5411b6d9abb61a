"""Rays: the Embree ray tracer with its bundle (global-visibility) queries, and the random and
quasi-random sequences."""
