"""National scale across regional centres (issue 17): protocol core for the published region model."""
