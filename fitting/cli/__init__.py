"""Command-line entry points of the `fitting` package (dispatched by `hertzchain`)."""
