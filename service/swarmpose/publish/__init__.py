"""Where results go: zenoh (live), files (replay) and the overlay video."""
