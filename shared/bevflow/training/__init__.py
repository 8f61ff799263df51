"""Training the person detector (optional: needs torch). The runtime in ``bevflow.detect`` never
imports this package."""
