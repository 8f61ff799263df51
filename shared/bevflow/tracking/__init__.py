"""The one world tracker that follows every person across the site."""
