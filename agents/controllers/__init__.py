"""Hand-written controllers and their pieces: the hand law, turning geometry, the fin map, the tank stop band."""
