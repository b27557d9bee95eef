"""friction-slide coulomb golden digest under CAND (candidates.py); compare with
tests/golden/trajectory_hashes.toml [friction."coulomb"]."""
import os, sys, warnings
sys.path.insert(0, os.path.dirname(__file__))
warnings.simplefilter("ignore")
import candidates  # noqa: F401
from wuerfel_cvx.lab.robustness.determinism import friction_digest
print(os.environ.get("CAND", "-"), friction_digest("coulomb"))
