"""``python -m exubio.cli``: the ``exubio`` command."""
from exubio.cli import run

if __name__ == "__main__":
    run()
