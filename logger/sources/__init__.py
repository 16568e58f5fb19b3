"""Data sources of the daemon: each one asyncio task feeding the writer's queue."""
