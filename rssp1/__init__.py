"""RSSP-I railway signal safety protocol: sans-IO core and thin UDP/TCP transports."""
