"""Small things every stage uses: conventions, errors, paths, atomic output, budget, the result record."""
