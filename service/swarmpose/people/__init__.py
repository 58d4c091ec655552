"""People and their identities: a track per person, associated frame to frame (stage 7b)."""
