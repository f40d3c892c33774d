//! Step control around impacts on a gap function, shared by the contacts
//! ([`super::contact`]) and the backlash of the gear pairs ([`super::gear`], each flank a gap).
//!
//! An element with a signed gap `g` (negative: penetration `delta = -g`), its rate `gdot`,
//! and a compliant force `K delta^n` (plus dissipation) in contact, between bodies of
//! effective mass `m*` along the gap's normal, asks of each converged step, from the gap and
//! its rate at the two ends ([`ImpactLaw::step_limit`]):
//!
//! The largest penetration the motion reaches from penetration `delta` and gap rate `gdot` is
//! `delta* = (delta^(n+1) + (n + 1) m* gdot^2 / (2 K))^(1 / (n + 1))` (the elastic energy
//! balance; an impact at speed `v` lasts about `2.94 delta* / v` for Hertz, Johnson 1985,
//! Sect. 11.4, and `pi delta* / v` for a linear spring). With `delta*` the larger from the two
//! ends of a step and `v` the larger gap rate:
//! - while the gap is closed, a step changes the penetration by at most `delta* / 12`: at
//!   most `h_c = delta* / (12 v)` long, `v` the larger of the gap rate and the speed of an
//!   impact reaching `delta*` (about 35 steps per impact), and at most as long as the last
//!   step's change of penetration allows; a step half as long again is repeated. A resting
//!   contact (gap rate below 1 % of the impact velocity that closed it, or, for an element
//!   that does not hold that velocity, of the speed of an impact reaching `delta*`: the
//!   vibration about the rest below 1 % of the penetration) is limited by the change of
//!   penetration only;
//! - a step that closes the gap deeper than `delta* / 12` is repeated to the time the gap,
//!   interpolated linearly, reaches half that much (event location on the gap);
//! - while the gap closes, the next step covers at most half the gap at the approach speed
//!   (but is not shorter than `h_c`): the steps shrink geometrically to the onset, which a
//!   step of about `h_c` crosses;
//! - a step that closes and opens the gap within itself (the cubic Hermite interpolant of
//!   `g, gdot` at both ends goes negative) is shortened to the first crossing.
//!
//! After the gap opens, the step grows back (doubling every 4 accepted steps,
//! [`crate::solve`]'s step control).

use super::StepLimit;

/// Penetration change per step allowed, as a fraction of the largest penetration of the
/// impact (`delta* / 12`).
const STEPS_PER_PENETRATION: f64 = 12.0;

/// A gap function at one end of a step.
#[derive(Clone, Copy, Debug)]
pub struct Gap {
    /// Signed gap g \[m\] (negative: penetration).
    pub gap: f64,
    /// Its rate gdot \[m/s\].
    pub rate: f64,
}

/// How a gap changed side in a step from `g0` to `g1` ([`super::ElementKernel::event`]):
/// `closes` from open (`g > 0`) to closed (`g < 0`), `opens` the other way. A step that starts
/// touching, `|g0|` at most `TOUCHING` (1e-9) times `|g1|` (a gap of 0 at t = 0 computed to
/// round-off), has not crossed: the force starts from zero there, and a contact's held
/// impact velocity is reset to the value it holds.
pub fn crossing(g0: f64, g1: f64) -> Option<&'static str> {
    if g0.abs() <= TOUCHING * g1.abs() {
        None
    } else if g0 > 0.0 && g1 < 0.0 {
        Some("closes")
    } else if g0 < 0.0 && g1 > 0.0 {
        Some("opens")
    } else {
        None
    }
}

/// A gap below this fraction of the next one is a touching start ([`crossing`]).
const TOUCHING: f64 = 1e-9;

/// The elastic part of a compliant contact force `K delta^n` between bodies of effective
/// mass `m*` along the gap's normal (infinite: no step control).
#[derive(Clone, Copy, Debug)]
pub struct ImpactLaw {
    /// K \[N/m^n\].
    pub stiffness: f64,
    /// n.
    pub exponent: f64,
    /// m* \[kg\].
    pub effective_mass: f64,
}

impl ImpactLaw {
    /// `delta*`, the largest penetration the motion reaches from penetration `delta` and gap
    /// rate `gdot` on the elastic path (module documentation).
    pub fn largest_penetration(&self, delta: f64, gdot: f64) -> f64 {
        let m1 = self.exponent + 1.0;
        let kinetic = m1 * self.effective_mass * gdot * gdot / (2.0 * self.stiffness);
        (delta.powf(m1) + kinetic).powf(1.0 / m1)
    }

    /// What a converged step of size `h` from `s0` to `s1` asks of the step control (module
    /// documentation). `impact_speed`: the impact velocity that closed the gap, if the
    /// element holds it (the resting test); `None` takes the speed of an impact reaching
    /// `delta*`.
    pub fn step_limit(
        &self,
        s0: Gap,
        s1: Gap,
        impact_speed: Option<f64>,
        h: f64,
    ) -> Option<StepLimit> {
        if !self.effective_mass.is_finite() || self.stiffness <= 0.0 {
            return None;
        }
        let (d0, d1) = ((-s0.gap).max(0.0), (-s1.gap).max(0.0));
        // The largest penetration the motion can reach (elastic energy balance) from
        // either end, and the speed the gap changes at.
        let depth = self
            .largest_penetration(d0, s0.rate)
            .max(self.largest_penetration(d1, s1.rate));
        let allowed = depth / STEPS_PER_PENETRATION;
        let rate = s0.rate.abs().max(s1.rate.abs());
        // The speed of the elastic motion: that of an impact reaching `depth`.
        let m1 = self.exponent + 1.0;
        let elastic = (2.0 * self.stiffness * depth.powf(m1) / (m1 * self.effective_mass)).sqrt();
        // Quiet: a resting contact, the impact that closed it spent.
        let quiet = rate < 0.01 * impact_speed.unwrap_or(elastic) && (d0 > 0.0) == (d1 > 0.0);
        let v = rate.max(elastic);
        // The step that resolves the contact: its penetration changes by `allowed` at most.
        let h_contact = if v > 0.0 && !quiet {
            allowed / v
        } else {
            f64::INFINITY
        };
        match (d0 > 0.0, d1 > 0.0) {
            (false, false) => {
                if s0.rate < 0.0 && s1.rate > 0.0 {
                    // Closed and opened again within the step if the cubic Hermite
                    // interpolant of the gap goes negative: shorten to the first crossing.
                    let hermite = |t: f64| {
                        let (t2, t3) = (t * t, t * t * t);
                        (2.0 * t3 - 3.0 * t2 + 1.0) * s0.gap
                            + (t3 - 2.0 * t2 + t) * h * s0.rate
                            + (-2.0 * t3 + 3.0 * t2) * s1.gap
                            + (t3 - t2) * h * s1.rate
                    };
                    if let Some(t) = (1..32).map(|k| k as f64 / 32.0).find(|&t| hermite(t) < 0.0) {
                        return Some(StepLimit::Retry(0.9 * t * h));
                    }
                }
                // Approaching: the next step covers half the gap at the approach speed, so
                // that the steps shrink geometrically to the onset.
                (s1.rate < 0.0).then(|| StepLimit::Next((0.5 * s1.gap / -s1.rate).max(h_contact)))
            }
            (false, true) if d1 > allowed => {
                // Closed too deep: repeat the step to the time the gap, interpolated
                // linearly, reaches -allowed / 2 (event location on the gap).
                let fraction = (s0.gap + 0.5 * allowed) / (s0.gap + d1);
                Some(StepLimit::Retry(fraction.clamp(0.01, 0.9) * h))
            }
            _ => {
                let change = (d1 - d0).abs();
                let by_change = if change > 0.0 {
                    h * allowed / change
                } else {
                    f64::INFINITY
                };
                let limit = h_contact.min(by_change);
                if h > 1.5 * limit {
                    Some(StepLimit::Retry(limit))
                } else {
                    limit.is_finite().then_some(StepLimit::Next(limit))
                }
            }
        }
    }
}
