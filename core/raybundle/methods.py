"""The methods by name: the registry the CLI, the bench and the add-on read.

Patch solvers (images and bakes) share :class:`~raybundle.solvers.StochasticIterationSolver`'s
interface; image-only methods (``image_only = True``: :class:`~raybundle.pathtracing.PathTracer`,
:class:`~raybundle.lighttracing.SingleRayIteration`) render camera images and have no patch
solution.  A module of its own so that every method can import the solver base class first.
"""
from .collocation import PointCollocationSolver
from .lighttracing import SingleRayIteration
from .pathtracing import PathTracer
from .radiosity import RadiositySolver
from .solvers import StochasticIterationSolver
from .walk import RayBundleWalk

#: the methods by name
SOLVERS = {StochasticIterationSolver.name: StochasticIterationSolver, RayBundleWalk.name: RayBundleWalk,
           RadiositySolver.name: RadiositySolver, PointCollocationSolver.name: PointCollocationSolver,
           PathTracer.name: PathTracer, SingleRayIteration.name: SingleRayIteration}


def image_only(method):
    """True for a method without a patch solution (it renders images, it does not bake and needs
    no patch layout)."""
    return bool(getattr(SOLVERS.get(method), "image_only", False))
