//! The paper's 1-DOF lumped torsional model, `I θ'' + c θ' + k θ = k Ω t + c Ω − T_bit(θ')`,
//! described by its inertia, natural frequency and damping ratio (the paper's Table 1 gives
//! I_eq = 383.33 kg·m², ω_n = 0.85 rad/s, ξ = 0.25).
//!
//! Linearised about steady rotation at the top-drive speed Ω, the bit-rock law enters only
//! through the bit damping c_b = r·dT/dw(Ω) (N·m·s/rad), and the Jacobian is
//! `[[0, 1], [−ω_n², −2ω_nξ − c_b/I]]`. Everything the maps need is therefore one scalar per
//! structure: the critical bit damping c_b* = −c_eq, below which steady rotation is unstable.

use crate::error::{Error, Result};

/// The equivalent single-degree-of-freedom drill string.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Lumped {
    /// Equivalent moment of inertia I_eq (kg·m²).
    pub inertia_kg_m2: f64,
    /// Natural frequency ω_n = √(k_eq / I_eq) (rad/s).
    pub omega_n_rad_s: f64,
    /// Damping ratio ξ = c_eq / (2 √(I_eq k_eq)) (dimensionless).
    pub damping_ratio: f64,
}

impl Default for Lumped {
    /// The paper's drill string (section "Results", 5 km well).
    fn default() -> Self {
        Self {
            inertia_kg_m2: 383.33,
            omega_n_rad_s: 0.85,
            damping_ratio: 0.25,
        }
    }
}

impl Lumped {
    /// Torsional stiffness k_eq = I ω_n² (N·m/rad).
    pub fn stiffness_nm_per_rad(&self) -> f64 {
        self.inertia_kg_m2 * self.omega_n_rad_s * self.omega_n_rad_s
    }

    /// Viscous damping c_eq = 2ξ√(I k) = 2ξ I ω_n (N·m·s/rad).
    pub fn damping_nms_per_rad(&self) -> f64 {
        2.0 * self.damping_ratio * self.inertia_kg_m2 * self.omega_n_rad_s
    }

    /// The critical bit damping c_b* = −c_eq (N·m·s/rad): steady rotation is unstable when the
    /// bit damping c_b = r·dT/dw(Ω) is at most this value, i.e. when the falling branch of the
    /// law removes more damping than the string provides.
    pub fn critical_bit_damping_nms(&self) -> f64 {
        -self.damping_nms_per_rad()
    }

    /// True when steady rotation with bit damping `bit_damping_nms` (N·m·s/rad) is unstable
    /// (the marginal case, a zero real part, counts as unstable, as in the paper).
    pub fn is_unstable(&self, bit_damping_nms: f64) -> bool {
        bit_damping_nms <= self.critical_bit_damping_nms()
    }

    /// Largest real part of the eigenvalues of the Jacobian
    /// `[[0, 1], [−ω_n², −2ω_nξ − c_b/I]]` (1/s): negative means perturbations of steady
    /// rotation decay at this rate, positive that they grow.
    ///
    /// Closed form of λ² + bλ + a = 0 with a = ω_n², b = (c_eq + c_b)/I. Writing b through
    /// c_eq + c_b makes the sign change exact at c_b = c_b*, and the real root is taken in the
    /// cancellation-free form −2a / (b + √(b² − 4a)) when b > 0.
    pub fn growth_rate(&self, bit_damping_nms: f64) -> f64 {
        let a = self.omega_n_rad_s * self.omega_n_rad_s;
        let b = (self.damping_nms_per_rad() + bit_damping_nms) / self.inertia_kg_m2;
        let discriminant = b * b - 4.0 * a;
        if discriminant < 0.0 {
            // Complex pair: both share the real part.
            -0.5 * b
        } else if b > 0.0 {
            -2.0 * a / (b + discriminant.sqrt())
        } else {
            0.5 * (-b + discriminant.sqrt())
        }
    }

    /// Refuses non-positive or non-finite values, naming the flag that set them.
    pub fn validate(&self) -> Result<()> {
        let checks = [
            ("inertia_kg_m2", self.inertia_kg_m2),
            ("omega_n_rad_s", self.omega_n_rad_s),
            ("damping_ratio", self.damping_ratio),
        ];
        for (field, value) in checks {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::setting(
                    field,
                    format!("must be positive and finite, got {value}"),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    #[test]
    fn paper_structure_has_the_expected_coefficients() {
        let s = Lumped::default();
        // k = 383.33 · 0.85² = 276.955925, c = 2 · 0.25 · 383.33 · 0.85 = 162.91525.
        assert!((s.stiffness_nm_per_rad() - 276.955_925).abs() < 1e-9);
        assert!((s.damping_nms_per_rad() - 162.915_25).abs() < 1e-9);
        // ξ recovered from the definition c / (2√(I k)).
        let xi = s.damping_nms_per_rad() / (2.0 * (s.inertia_kg_m2 * s.stiffness_nm_per_rad()).sqrt());
        assert!((xi - 0.25).abs() < 1e-12);
    }

    #[test]
    fn growth_rate_changes_sign_exactly_at_the_critical_damping() {
        for s in [
            Lumped::default(),
            Lumped {
                inertia_kg_m2: 2.0,
                omega_n_rad_s: 30.0,
                damping_ratio: 0.02,
            },
        ] {
            let crit = s.critical_bit_damping_nms();
            assert!(s.growth_rate(crit).abs() < 1e-15, "{}", s.growth_rate(crit));
            let below = crit - crit.abs() * 1e-9;
            let above = crit + crit.abs() * 1e-9;
            assert!(s.growth_rate(below) > 0.0);
            assert!(s.growth_rate(above) < 0.0);
            assert!(s.is_unstable(crit) && s.is_unstable(below) && !s.is_unstable(above));
        }
    }

    #[test]
    fn growth_rate_matches_the_eigenvalues_of_the_jacobian() {
        let s = Lumped::default();
        let i = s.inertia_kg_m2;
        let wn = s.omega_n_rad_s;
        // Under- and overdamped, stable and unstable, zero bit damping.
        for cb in [-5000.0, -400.0, -162.0, 0.0, 250.0, 1000.0, 5000.0] {
            let j = Matrix2::new(0.0, 1.0, -wn * wn, -2.0 * wn * s.damping_ratio - cb / i);
            let eig = j.complex_eigenvalues();
            let expected = eig[0].re.max(eig[1].re);
            let got = s.growth_rate(cb);
            assert!(
                (got - expected).abs() < 1e-12 * (1.0 + expected.abs()),
                "c_b={cb}: {got} vs {expected}"
            );
        }
    }

    #[test]
    fn validation_names_the_setting() {
        let bad = |s: Lumped| s.validate().unwrap_err().to_string();
        let base = Lumped::default();
        assert!(base.validate().is_ok());
        assert!(
            bad(Lumped {
                inertia_kg_m2: 0.0,
                ..base
            })
            .starts_with("`inertia_kg_m2`:")
        );
        assert!(
            bad(Lumped {
                omega_n_rad_s: f64::NAN,
                ..base
            })
            .starts_with("`omega_n_rad_s`:")
        );
        assert!(
            bad(Lumped {
                damping_ratio: -0.1,
                ..base
            })
            .starts_with("`damping_ratio`:")
        );
    }
}
