"""Engines that run a graph: offline, live ring, callback, PortAudio, JACK, haptic frames,
probe input and OSC."""
