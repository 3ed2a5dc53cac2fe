"""The levelmap error-against-time sweep: the spec ``specs/levelmap_sweep.json`` run by ``refraction-ref sweep``."""
import os, sys  # noqa: E401
from refraction_ref.cli import main  # extra arguments go to the verb: --workers N, --scheduler tcp://HOST:PORT
SPEC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "specs", "levelmap_sweep.json")
if __name__ == "__main__":
    sys.exit(main(["sweep", SPEC, "--out", os.path.join(os.path.dirname(SPEC), "..", "results"), *sys.argv[1:]]))
