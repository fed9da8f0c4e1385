"""Training: learners, self-play games and the league in one loop."""
