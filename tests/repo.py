"""Where the repository is, for tests that read its files (config, messages, URDF) wherever they sit."""
import os

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
