"""Track topology: the line's tracks, switches and trackside elements (model, file format, railML import)."""
