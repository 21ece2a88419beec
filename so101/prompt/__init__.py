"""The keyboard prompt: the command language, saved poses, terminal keys, jogging, and what each command does."""
