"""The methods by name: the registry the CLI, the bench and the add-on read.

Patch solvers (images and bakes) share :class:`~raybundle.solvers.StochasticIterationSolver`'s
interface; image-only methods (``image_only = True``) render camera images and have no patch
solution.  A module of its own so that every method can import the solver base class first.
"""
from .pathtracing import PathTracer
from .radiosity import RadiositySolver
from .solvers import StochasticIterationSolver
from .walk import RayBundleWalk

#: the methods by name
SOLVERS = {StochasticIterationSolver.name: StochasticIterationSolver, RayBundleWalk.name: RayBundleWalk,
           RadiositySolver.name: RadiositySolver, PathTracer.name: PathTracer}


def image_only(method):
    """True for a method without a patch solution (it renders images, it does not bake and needs
    no patch layout): :class:`~raybundle.pathtracing.PathTracer`."""
    return bool(getattr(SOLVERS.get(method), "image_only", False))
