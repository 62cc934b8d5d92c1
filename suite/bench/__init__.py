"""Speed figures (`python -m suite bench TARGET`): medians over repeated runs, printed, never asserted."""
