"""``bevflow serve webhook``: the site's alerts POSTed to a URL, signed, retried until delivered."""
