"""Crop input and what it asks for: sensor lines to NDVI at the meters, NDVI to a rate."""
