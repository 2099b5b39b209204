"""``python -m navarena``: the ``navarena`` command (navarena/cli.py)."""
from navarena.cli import main

if __name__ == "__main__":
    main()
