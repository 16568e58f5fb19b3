"""Digital elevation models read from local files (never downloaded at run time)."""
