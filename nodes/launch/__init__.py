"""``ppod up``: start the stack's nodes as separate processes and manage their lifecycles."""
