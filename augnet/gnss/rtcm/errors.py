"""The codec's two exception types: bad bytes in, or values that a message cannot carry."""


class DecodeError(ValueError):
    """A CRC-valid payload that does not hold the message its type announces (e.g. too short)."""


class EncodeError(ValueError):
    """Field values that the message cannot carry (missing, out of range, too many cells)."""
