"""The methods by name: the registry the CLI, the bench and the add-on read.

Every method is a :class:`~raybundle.methods.base.Method` (its name and what it can do), one
per module: patch solvers (images and bakes) derive from
:class:`~raybundle.methods.patch_solution.PatchSolution`;
image-only methods (:class:`~raybundle.methods.path_tracing.PathTracer`,
:class:`~raybundle.methods.single_ray_iteration.SingleRayIteration`) render camera images and have
no patch solution.
"""
from .path_tracing import PathTracer
from .point_collocation import PointCollocationSolver
from .radiosity import RadiositySolver
from .ray_bundle_walk import RayBundleWalk
from .single_ray_iteration import SingleRayIteration
from .stochastic_iteration import StochasticIterationSolver

#: the methods by name
SOLVERS = {StochasticIterationSolver.name: StochasticIterationSolver, RayBundleWalk.name: RayBundleWalk,
           RadiositySolver.name: RadiositySolver, PointCollocationSolver.name: PointCollocationSolver,
           PathTracer.name: PathTracer, SingleRayIteration.name: SingleRayIteration}


def image_only(method):
    """True for a method without a patch solution (it renders images, it does not bake and needs
    no patch layout)."""
    return method in SOLVERS and SOLVERS[method].image_only
