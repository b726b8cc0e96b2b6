"""Kinematics of one configuration: what every task of a step reads, computed once.

In the spirit of pink's ``Configuration``: :meth:`Kinematics.update` runs Pinocchio's
``computeJointJacobians`` (forward kinematics and every joint's Jacobian, world axes) once per
configuration; tasks then ask for frame placements and frame Jacobians, which Pinocchio derives
from that state without recomputing the kinematics.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

_LOCAL = pin.LOCAL
_WORLD_ALIGNED = pin.LOCAL_WORLD_ALIGNED


class Kinematics:
    """Pinocchio's model and a ``data`` of its own, at the configuration ``q`` of the last
    :meth:`update` (each solver has one, so solvers never share scratch space). Jacobians are
    always 2-D, (6, nv), also for a robot with one joint (Pinocchio returns a vector there).

    What a task's ``compute`` (or a limit's ``bounds``/``rows``) may read:

    - ``model``, ``data``: Pinocchio's, after ``computeJointJacobians`` at ``q``: the joint
      placements ``data.oMi`` and the joint Jacobians ``data.J`` (world axes) are current, so
      Pinocchio's frame functions (``getFrameJacobian``, ``updateFramePlacement``, ...) and
      ``jacobianCenterOfMass(model, data)`` need no other kinematics call;
    - ``q`` (nq,): the configuration;
    - :meth:`placement`, :meth:`jacobian` (LOCAL), :meth:`world_aligned_jacobian`,
      :meth:`center_of_mass` (computed once per configuration, shared) and :meth:`difference`.
    """

    __slots__ = ("model", "data", "q", "jacobian", "world_aligned_jacobian", "_com_fresh",
                 "_zero", "_com")

    def __init__(self, model: pin.Model):
        self.model = model
        self.data = model.createData()
        self.q: np.ndarray | None = None
        self._com_fresh = False
        self._zero = np.zeros(model.nv)
        #: views of ``data.com[0]`` and ``data.Jcom`` (Pinocchio writes both in place; taking
        #: the views anew cost 0.7 us a step)
        self._com: tuple[np.ndarray, np.ndarray] | None = None
        if model.nv == 1:
            self.jacobian = self._column(pin.LOCAL)
            self.world_aligned_jacobian = self._column(pin.LOCAL_WORLD_ALIGNED)
        else:
            self.jacobian = self._local_jacobian
            self.world_aligned_jacobian = self._aligned_jacobian

    def update(self, q: np.ndarray) -> None:
        """Forward kinematics and joint Jacobians at ``q`` (nq,), validated by the caller."""
        pin.computeJointJacobians(self.model, self.data, q)
        self.q = q
        self._com_fresh = False

    def velocity_products(self, v: np.ndarray) -> None:
        """Forward kinematics at ``q`` with the velocity ``v`` (nv,) and no acceleration: each
        frame's acceleration (``getFrameAcceleration``, ``getFrameClassicalAcceleration``) is
        then its velocity-product term ``J_dot v`` alone. The placements and joint Jacobians
        stay those of :meth:`update` (the same ``q``)."""
        pin.forwardKinematics(self.model, self.data, self.q, v, self._zero)

    def center_of_mass(self) -> tuple[np.ndarray, np.ndarray]:
        """``(c, J_c)``: the robot's centre of mass (3,; m, world axes) and its Jacobian
        ``dc/dq`` (3, nv), Pinocchio's ``data.com[0]`` and ``data.Jcom``, computed once per
        configuration from the joint Jacobians of :meth:`update` (views, overwritten by the
        next configuration's)."""
        if not self._com_fresh:
            pin.jacobianCenterOfMass(self.model, self.data, False)
            self._com_fresh = True
        com = self._com
        if com is None:  # (a robot of one velocity coordinate: Pinocchio gives Jcom as (3,))
            com = self._com = (self.data.com[0], self.data.Jcom.reshape(3, self.model.nv))
        return com

    def placement(self, frame_id: int) -> pin.SE3:
        """World pose ``oMf`` of frame ``frame_id`` (a copy)."""
        return pin.updateFramePlacement(self.model, self.data, frame_id)

    def _local_jacobian(self, frame_id: int) -> np.ndarray:
        """Frame Jacobian (6, nv), rows [linear; angular], in the frame's LOCAL axes
        (``jacobian``)."""
        return pin.getFrameJacobian(self.model, self.data, frame_id, _LOCAL)

    def _aligned_jacobian(self, frame_id: int) -> np.ndarray:
        """Frame Jacobian (6, nv) at the frame's origin in world axes (LOCAL_WORLD_ALIGNED;
        ``world_aligned_jacobian``)."""
        return pin.getFrameJacobian(self.model, self.data, frame_id, _WORLD_ALIGNED)

    def _column(self, reference):
        def jacobian(frame_id: int) -> np.ndarray:
            J = pin.getFrameJacobian(self.model, self.data, frame_id, reference)
            return np.ascontiguousarray(J).reshape(6, 1)

        return jacobian

    def difference(self, q_ref: np.ndarray) -> np.ndarray:
        """``q_ref ⊖ q`` (nv,): the tangent vector that integrates ``q`` into ``q_ref``."""
        return pin.difference(self.model, self.q, q_ref)
