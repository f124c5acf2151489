"""Scenes and rays: the :class:`Scene` type, mesh files, the registry of named meshes, procedural,
SPD and derived scenes, and seeded ray sets. Nothing here imports :mod:`tracer.accel`."""
