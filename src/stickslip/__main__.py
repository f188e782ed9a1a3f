"""``python -m stickslip ...`` runs the command line, as ``stickslip ...`` does.

Useful where the virtual environment's scripts folder is not on the PATH (a Windows
lab PC, a notebook's ``!python -m stickslip where``).
"""

from stickslip.cli import main

if __name__ == "__main__":
    main()
