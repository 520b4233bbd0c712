"""test/ holds shared helpers (graphproc, bagcheck, mathfixtures); the tests in its subfolders import them."""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
