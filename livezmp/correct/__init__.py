"""Balance corrections: root (waist) rotations and the leg joints that keep the feet, offline and online."""
