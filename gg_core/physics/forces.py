"""Force library: extra physical effects as named terms of the incremental potential, switched on by name.

Dissipative forces enter an implicit step through a dissipation potential whose gradient in the end position
x is minus the force at the step's velocity v = (x - x_t)/dt (e.g. drag c|v_n|v_n <- dt c |v_n|^3 / 3), so every
effect is a Term with a torch energy and a fast assemble(). Effects that need no force term are material
fields instead: a heavy patch is per-vertex density, a seam or elastic band is per-edge rest length.

`TERMS` holds every term by name (base terms included); `DEFAULT_TERMS` is the model used when nothing else is
asked for; `make_terms` builds a term list from names and parameter overrides (the diagnosis adds terms here).
"""
from __future__ import annotations

from typing import Any, Iterable

import numpy as np
import torch

from . import kernels
from .energies import BASE_TERMS, dihedral_angles, face_q
from .terms import StepInputs, Term


def _vel(x, step: StepInputs):
    return (x - step.x_prev) / step.dt


class BodyFriction(Term):
    """Coulomb friction against the body: opposes the garment's slip relative to the body surface at each contact,
    with coefficient `mu` and the collision penalty's normal force, lagged: at the start state, or at the step's
    own contact solution (SolverOptions.friction_at_end); smoothed below `slip` (m/s) so that sticking is a stiff
    spring instead of a discontinuity (IPC-style lagged friction potential)."""

    name = "body_friction"
    defaults = {"mu": 0.5, "slip": 0.01}

    def _slip(self, x, step):
        u = x - step.x_prev - step.contact_motion
        n = step.contact_normal
        return u - (u * n).sum(-1, keepdims=True) * n

    def energy(self, x, step, rest):
        u = self._slip(x, step)
        eps = self.params["slip"] * step.dt
        y = torch.sqrt((u * u).sum(-1) + 1e-30)
        f0 = torch.where(y < eps, y * y / eps - y ** 3 / (3 * eps * eps) + eps / 3, y)
        return (self.params["mu"] * step.contact_force * step.contact_active * f0).sum(-1)

    def assemble(self, x, step, num, system):
        u = self._slip(x, step)
        eps = self.p("slip") * step.dt
        y = np.sqrt((u * u).sum(1) + 1e-30)
        small = y < eps
        f0 = np.where(small, y * y / eps - y ** 3 / (3 * eps * eps) + eps / 3, y)
        w = self.p("mu") * step.contact_force * step.contact_active
        if system is not None:
            f1_over_y = np.where(small, 2 / eps - y / (eps * eps), 1 / y)
            s = w * f1_over_y
            n = step.contact_normal
            tangent = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
            system.add_vertex(s[:, None] * u, hess=s[:, None, None] * tangent)
        return float((w * f0).sum())


class Wind(Term):
    """Quadratic aerodynamic drag against a moving air mass: force -coef A |v_n| v_n n per vertex, with
    v_n = (v - wind) . n the normal relative velocity, A the vertex area, n the cloth normal at the step start and
    coef = rho_air C_d / 2 (kg/m^3). Pushes windward regions even at rest."""

    name = "wind"
    defaults = {"coef": 0.6, "velocity": (0.0, 0.0, 1.0)}

    def _air(self) -> Any:
        return self.params["velocity"]

    def energy(self, x, step, rest):
        vn = ((_vel(x, step) - self._air()) * step.normal_prev).sum(-1)
        return (step.dt * self.params["coef"] * rest.vertex_area * vn.abs() ** 3 / 3).sum(-1)

    def assemble(self, x, step, num, system):
        n = step.normal_prev
        air = self._air()
        air = air.detach().numpy() if isinstance(air, torch.Tensor) else air
        vn = ((_vel(x, step) - air) * n).sum(1)
        c = self.p("coef") * num.vertex_area
        if system is not None:
            system.add_vertex((c * np.abs(vn) * vn)[:, None] * n,
                              hess=(2 * c * np.abs(vn) / step.dt)[:, None, None] * n[:, :, None] * n[:, None, :])
        return float((step.dt * c * np.abs(vn) ** 3 / 3).sum())


class WindPressure(Term):
    """Steady wind as a pressure on the cloth: force A (n . w) n per vertex, w the pressure vector (Pa) and n the
    cloth normal at the step start, independent of the cloth's velocity (as Blender's wind field acts on cloth
    faces). Pushes regions facing the wind even at rest, vanishes where the cloth lies along it; linear in w."""

    name = "wind_pressure"
    defaults = {"pressure": (0.0, 0.0, 0.0)}

    def energy(self, x, step, rest):
        n = step.normal_prev
        return -(rest.vertex_area * (n * self.params["pressure"]).sum(-1) * (n * x).sum(-1)).sum(-1)

    def assemble(self, x, step, num, system):
        n = step.normal_prev
        force = (num.vertex_area * (n @ self.p("pressure")))[:, None] * n
        if system is not None:
            system.add_vertex(-force)
        return float(-(force * x).sum())


class AirDrag(Wind):
    """Quadratic aerodynamic drag in still air: force -coef A |v_n| v_n n per vertex (v_n the normal velocity,
    A the vertex area, coef = rho_air C_d / 2 in kg/m^3). Strongest on large free panels at peak speed."""

    name = "air_drag"
    defaults = {"coef": 0.6}

    def _air(self) -> Any:
        return torch.zeros(3, dtype=torch.float64)


class MassDamping(Term):
    """Rayleigh mass damping: force -alpha m v on every vertex (alpha in 1/s), isotropic and everywhere; for
    uniform density the same as linear air drag. Part of the default model at 1/s, the order of Blender's default
    cloth air damping (air_damping 1 is 0.01 fps / vertex mass per second: 0.8/s at 24 fps and 0.3 kg)."""

    name = "mass_damping"
    defaults = {"alpha": 1.0}

    def energy(self, x, step, rest):
        v = _vel(x, step)
        return (0.5 * step.dt * self.params["alpha"] * rest.mass * (v * v).sum(-1)).sum(-1)

    def assemble(self, x, step, num, system):
        v = _vel(x, step)
        am = self.p("alpha") * num.mass
        if system is not None:
            system.add_vertex(am[:, None] * v, iso=am / step.dt)
        return float((0.5 * step.dt * am * (v * v).sum(1)).sum())


class StrainRateDamping(Term):
    """Internal (material) damping: each edge resists its strain rate with force beta * d(strain)/dt along the
    edge (beta in N s). Zero for rigid motion, so it damps stretch waves and impacts, not swinging."""

    name = "strain_rate_damping"
    defaults = {"beta": 0.01}

    @staticmethod
    def _lengths(x, edges):
        d = x[..., edges[:, 0], :] - x[..., edges[:, 1], :]
        return (d * d).sum(-1) ** 0.5

    def _beta(self, rest) -> Any:
        """Damping coefficient of every edge (N s; a scalar here, per edge in subclasses)."""
        return self.params["beta"]

    def _beta_numeric(self, num) -> Any:
        return self.p("beta")

    def energy(self, x, step, rest):
        rate = (self._lengths(x, rest.edges) - self._lengths(step.x_prev, rest.edges)) / (rest.rest_lengths * step.dt)
        return (0.5 * self._beta(rest) * rest.rest_lengths * step.dt * rate * rate).sum(-1)

    def assemble(self, x, step, num, system):
        L = num.rest_lengths
        rate = (kernels.edge_lengths(x, num.edges) - kernels.edge_lengths(step.x_prev, num.edges)) / (L * step.dt)
        beta = self._beta_numeric(num)
        if system is not None:
            system.add_edge(x, beta * rate, beta / (L * step.dt) * np.ones_like(L))
        return float((0.5 * beta * L * step.dt * rate * rate).sum())


class ViscoelasticDamping(StrainRateDamping):
    """Kelvin-Voigt internal damping: each edge resists its stretching rate with `tau` (s, the retardation time)
    times its own stretching stiffness, k_e = 8 L_e^2 sum over its faces of the membrane's diagonal edge-length
    coefficient C_kk (d^2 psi / dl^2 at rest). Stiffness-proportional (Rayleigh) damping: the loss factor is about
    2 pi f tau at frequency f whatever the material, so a fit that rescales density and stiffness together (motion
    only sees their ratio) keeps the same relative damping, which a fixed beta in N s does not."""

    name = "viscoelastic_damping"
    defaults = {"tau": 0.01}
    # fabrics are viscoelastic solids (loss tangent typically below 0.3): a fit may not make the membrane more
    # viscous than elastic (loss factor 1) at walking and swinging frequencies (1 Hz)
    limits = {"tau": 1.0 / (2.0 * np.pi * 1.0)}

    def _beta(self, rest) -> Any:
        diag = rest.stretch_c.diagonal(dim1=-2, dim2=-1)
        k = torch.zeros_like(rest.rest_lengths).index_add(0, rest.face_edges.reshape(-1), diag.reshape(-1))
        return self.params["tau"] * 8.0 * rest.rest_lengths ** 3 * k

    def _beta_numeric(self, num) -> Any:
        diag = np.diagonal(num.stretch_c, axis1=-2, axis2=-1)
        k = np.bincount(num.face_pairs.ravel(), diag.ravel(), minlength=len(num.rest_lengths))
        return self.p("tau") * 8.0 * num.rest_lengths ** 3 * k


class BendingDamping(Term):
    """Kelvin-Voigt damping of bending: each hinge resists its folding rate with `tau` (s) times its own bending
    stiffness, force -2 c tau d(theta)/dt for the bending energy c (theta - theta_0)^2. The membrane's
    viscoelastic_damping only sees edge stretching rates, which a fold barely has. Blender's reference cloth damps
    its bending springs in proportion to their stiffness too (bending_damping), and relatively more than its
    stretching springs (cotton preset: 0.5 / 0.5 against 5 / 15). In the step's potential:
    (tau c / dt) (theta(x) - theta(x_t))^2, a hinge energy towards the start state's angles."""

    name = "bending_damping"
    defaults = {"tau": 0.01}
    limits = {"tau": 1.0 / (2.0 * np.pi * 1.0)}     # loss factor at most 1 at 1 Hz, as the membrane's

    def energy(self, x, step, rest):
        d = dihedral_angles(x, rest.hinges) - dihedral_angles(step.x_prev, rest.hinges)
        return (self.params["tau"] / step.dt * rest.hinge_coef * d * d).sum(-1)

    def assemble(self, x, step, num, system):
        start = kernels.hinge_angles(step.x_prev, num.hinges)
        coef = self.p("tau") / step.dt * num.hinge_coef
        if system is None:
            return float(kernels.hinge_energy(x, num.hinges, coef, start))
        return float(kernels.hinge_assemble(x, num.hinges, num.hinge_pairs, coef, start,
                                            system.grad, system.hdiag, system.hpair))


def _material_directions(template: np.ndarray, faces: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """[F,2] unit 2D direction in each face's rest frame (edge 0 along x) of a 3D template direction."""
    tri = template[faces]
    t1 = tri[:, 1] - tri[:, 0]
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    u = np.stack([t1 @ direction, t2 @ direction], 1)
    norm = np.linalg.norm(u, axis=1, keepdims=True)
    return np.where(norm > 1e-6, u / np.maximum(norm, 1e-12), np.array([1.0, 0.0]))


class AnisotropicStretch(Term):
    """Woven-fabric anisotropy: extra stiffness along the warp and weft yarns, psi = V (k_warp E_uu^2 +
    k_weft E_vv^2) with E the Green strain, u the warp direction (`direction` in the template, projected into each
    face) and v the weft direction perpendicular to it in the cloth plane. k in Pa like Lame mu."""

    name = "anisotropic_stretch"
    defaults = {"k_warp": 2.0e4, "k_weft": 0.0, "direction": (0.0, 1.0, 0.0)}

    def _betas(self, basis, template, faces):
        """beta_u, beta_v [F,3]: E_uu = beta_u . q, E_vv = beta_v . q."""
        tmpl = template.detach().numpy() if isinstance(template, torch.Tensor) else template
        fcs = faces.numpy() if isinstance(faces, torch.Tensor) else faces
        u = _material_directions(tmpl, fcs, np.asarray(self.params["direction"].detach().numpy(), np.float64))
        v = np.stack([-u[:, 1], u[:, 0]], 1)
        if isinstance(basis, torch.Tensor):
            u, v = torch.from_numpy(u), torch.from_numpy(v)
            return torch.einsum("fa,fkab,fb->fk", u, basis, u), torch.einsum("fa,fkab,fb->fk", v, basis, v)
        return np.einsum("fa,fkab,fb->fk", u, basis, u), np.einsum("fa,fkab,fb->fk", v, basis, v)

    def energy(self, x, step, rest):
        bu, bv = self._betas(rest.strain_basis, rest.template, rest.faces)
        q = face_q(x, rest.faces, rest.face_rest_sq)
        vol = rest.thickness * rest.face_area
        warp, weft = (q * bu).sum(-1) ** 2, (q * bv).sum(-1) ** 2
        return (vol * (self.params["k_warp"] * warp + self.params["k_weft"] * weft)).sum(-1)

    def assemble(self, x, step, num, system):
        bu, bv = self._betas(num.strain_basis, num.template, num.faces)
        q = kernels.face_q_values(x, num.faces, num.face_rest_sq)
        vol = num.thickness * num.face_area
        kw, kf = self.p("k_warp") * vol, self.p("k_weft") * vol
        eu, ev = (q * bu).sum(1), (q * bv).sum(1)
        if system is not None:
            system.add_face_q(2 * (kw * eu)[:, None] * bu + 2 * (kf * ev)[:, None] * bv,
                              2 * kw[:, None, None] * bu[:, :, None] * bu[:, None, :]
                              + 2 * kf[:, None, None] * bv[:, :, None] * bv[:, None, :])
        return float((kw * eu * eu + kf * ev * ev).sum())


class StrainStiffening(Term):
    """Nonlinear (J-shaped) stiffening of the membrane at large strain: psi = V k tr(E^2)^2 (k in Pa), negligible
    at small strain and dominant at load peaks, unlike a stiffer linear mu."""

    name = "strain_stiffening"
    defaults = {"k": 1.0e6}

    def energy(self, x, step, rest):
        q = face_q(x, rest.faces, rest.face_rest_sq)
        t = torch.einsum("fkab,flba->fkl", rest.strain_basis, rest.strain_basis)
        s = torch.einsum("...fk,fkl,...fl->...f", q, t, q)
        return (self.params["k"] * rest.thickness * rest.face_area * s * s).sum(-1)

    def assemble(self, x, step, num, system):
        q = kernels.face_q_values(x, num.faces, num.face_rest_sq)
        t = np.einsum("fkab,flba->fkl", num.strain_basis, num.strain_basis)
        tq = np.einsum("fkl,fl->fk", t, q)
        s = (q * tq).sum(1)
        kv = self.p("k") * num.thickness * num.face_area
        if system is not None:
            system.add_face_q((4 * kv * s)[:, None] * tq,
                              2 * kv[:, None, None] * (4 * tq[:, :, None] * tq[:, None, :] + 2 * s[:, None, None] * t))
        return float((kv * s * s).sum())


class GravityOffset(Term):
    """A uniform extra acceleration delta_g (m/s^2) on every mass: a mis-set or tilted gravity, or a steady
    inertial frame acceleration. Uniform and constant, unlike wind which depends on the cloth normal."""

    name = "gravity_offset"
    defaults = {"delta_g": (0.0, 0.0, 0.0)}

    def energy(self, x, step, rest):
        return -(rest.mass * (x * self.params["delta_g"]).sum(-1)).sum(-1)

    def assemble(self, x, step, num, system):
        mg = num.mass[:, None] * self.p("delta_g")
        if system is not None:
            system.add_vertex(-mg)
        return float(-(mg * x).sum())


LIBRARY: tuple[type[Term], ...] = (BodyFriction, AirDrag, Wind, WindPressure, MassDamping, StrainRateDamping,
                                   ViscoelasticDamping, BendingDamping, AnisotropicStretch, StrainStiffening,
                                   GravityOffset)
TERMS: dict[str, type[Term]] = {cls.name: cls for cls in BASE_TERMS + LIBRARY}
# every cloth simulator damps: without it a rollout keeps the energy that real fabric loses to air and internal
# friction, and the diagnosis finds "missing damping" in every recording (measured on the benchmark's `none` case)
DEFAULT_TERMS: tuple[str, ...] = ("inertia", "gravity", "stretching", "bending", "collision", "body_friction",
                                  "mass_damping")


def make_terms(names: Iterable[str] = DEFAULT_TERMS, params: dict[str, dict[str, Any]] | None = None) -> list[Term]:
    """Instantiate terms by name; `params` maps a term name to parameter overrides. Inertia comes first."""
    params = params or {}
    names = list(dict.fromkeys(names))
    unknown = [n for n in list(names) + list(params) if n not in TERMS]
    if unknown:
        raise ValueError(f"unknown force terms {unknown}; known: {', '.join(TERMS)}")
    missing = [n for n in params if n not in names]
    if missing:
        raise ValueError(f"parameters given for terms that are not switched on: {missing}")
    if "inertia" not in names:
        names.insert(0, "inertia")
    return [TERMS[n](**params.get(n, {})) for n in names]


def parse_term_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """'wind:velocity=1;0;0,coef=0.6' -> ('wind', {'velocity': (1.0, 0.0, 0.0), 'coef': 0.6}) (command lines)."""
    name, _, rest = spec.partition(":")
    params: dict[str, Any] = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        try:
            numbers = tuple(float(v) for v in value.split(";"))
        except ValueError:
            numbers = ()
        if not eq or not numbers:
            raise ValueError(f"term parameter '{item}' of '{spec}' is not KEY=NUMBER or KEY=X;Y;Z")
        params[key] = numbers[0] if len(numbers) == 1 else numbers
    return name, params
