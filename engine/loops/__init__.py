"""Loop detection: the paper's three methods (``paper``) and ``verified`` (the stages of this
package, in the order they run). ``LoopCandidate`` is what every method returns."""

from .paper import LoopCandidate, detect_loops, similarity_matrix

__all__ = ["LoopCandidate", "detect_loops", "similarity_matrix"]
