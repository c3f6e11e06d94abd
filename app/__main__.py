"""`python -m app` runs the roadview CLI."""

from app.cli import main

main()
