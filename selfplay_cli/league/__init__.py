"""League training utilities: opponent pools, match scheduling and rating/evaluation statistics."""
