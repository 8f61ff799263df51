"""Pure logic of the live pipeline: ordering camera results into ticks, one site tracker step."""
