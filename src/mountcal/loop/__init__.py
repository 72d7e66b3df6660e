"""Closing the loop: model choice, residual tests, change points, slope reference, systematic σ."""
