"""Pieces shared by the algorithms of sb3_dtdpg: noise, phases, callbacks, replay buffers."""
