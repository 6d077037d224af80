"""Level 3 of UniTrack: task heads built from the appearance model and the primitives."""
