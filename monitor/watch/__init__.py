"""`monitor watch`: what a running monitor reports, read off the bus and drawn in a terminal."""
