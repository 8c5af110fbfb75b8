"""2D elastic rods as chains of constant-curvature arcs (super-circles), with frictional contact.

Models: arc (element kinematics, stable moments, Jacobians), model (RodModel,
RodState, Arcs, PointLoad), chained (reduced coordinates, dense), mixed (per-element unknowns
glued by constraints, banded KKT, linear in n), statics (Newton-KKT static solver), modes
(flexural modes -> jassy ModalModel), elastic_experiments, bench.
Contact: geometry, dfcp, system, contact_experiments.
Submodules are imported explicitly (``from physics.rod.mixed import MixedRod``).
"""
