"""`augnet up`: the whole system in one process (see runtime.py)."""
