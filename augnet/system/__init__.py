"""`augnet up`: the whole system from one command (see runtime.py); the centre runs in a process of its own
(centre_service.py)."""
