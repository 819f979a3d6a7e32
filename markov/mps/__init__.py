"""Matrix product forms of open roads (issue 35): the one-step matrix as an MPO."""
from markov.mps.road_mpo import RoadMPO, compress, ones_invariance, road_mpo, to_dense

__all__ = ["RoadMPO", "compress", "ones_invariance", "road_mpo", "to_dense"]
