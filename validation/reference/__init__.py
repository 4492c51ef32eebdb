"""Reference codes the engine is checked against: LIGGGHTS-PUBLIC 3.8 (``liggghts``), its
contact-level cases and experiment-level decks written from the project's own definitions."""
