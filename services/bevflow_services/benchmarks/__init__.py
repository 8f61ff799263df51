"""bevflow's benchmarks, one module per part, run together by ``bevflow bench``.

``cylinder`` (the cylinder fit against its reference), ``tracking`` (the tracker service's tick:
fusion + tracking + analytics), ``detector``, ``live`` (the running system end to end), ``gateway``
(REST and websocket fan-out) and ``bus``; ``suite`` runs them and ``report`` prints the results.
Each module also runs alone: ``python -m bevflow_services.benchmarks.<part> --help``.
"""
