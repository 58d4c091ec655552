"""The names ``swarmpose bench utdmhad`` chooses from: UTD-MHAD's subjects and actions, and the
shapes the benchmark gives them (:mod:`swarmpose.bench.utdmhad` runs it). A module of its own,
without imports, so the command line's parser gets them without the benchmark's."""

from __future__ import annotations

SUBJECTS = ("s1", "s2", "s3")
SHAPES = ("default", "measured")

ACTIONS = {
    1: "swipe left", 2: "swipe right", 3: "wave", 4: "clap", 5: "throw", 6: "arm cross", 7: "basketball shoot",
    8: "draw x", 9: "draw circle (cw)", 10: "draw circle (ccw)", 11: "draw triangle", 12: "bowling", 13: "boxing",
    14: "baseball swing", 15: "tennis swing", 16: "arm curl", 17: "tennis serve", 18: "push", 19: "knock",
    20: "catch", 21: "pickup & throw", 22: "jog", 23: "walk", 24: "sit to stand", 25: "stand to sit",
    26: "lunge", 27: "squat",
}
"""UTD-MHAD's 27 actions (from the dataset's paper)."""
