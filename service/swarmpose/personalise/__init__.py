"""Fitting the body to the person: the automatic height and personalisation of the shape."""
