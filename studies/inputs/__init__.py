"""What a user writes: the scene and study models, units on input, isolator presets, parameter paths,
and how a scene and a study become the engine's batches.
"""
