//! The values an option accepts. Each numeric option's bounds are written once, as a constant
//! beside its options struct: the struct's `validate` checks values against that constant, and
//! `tools/gen-header` prints it into the field's C doc ("Range: ..."), so that no range is
//! written by hand in the C, C++ or Python docs.

use std::fmt;

/// The values a numeric option accepts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bounds {
    /// Whole numbers from `min` up to `max` (both included; `None`: no upper bound).
    Whole {
        /// Smallest accepted value.
        min: u64,
        /// Largest accepted value, if any.
        max: Option<u64>,
    },
    /// Finite reals between two ends, each included or not; an infinite end is no bound.
    Real {
        /// Lower end (`f64::NEG_INFINITY`: none).
        min: f64,
        /// Whether `min` itself is accepted.
        min_included: bool,
        /// Upper end (`f64::INFINITY`: none).
        max: f64,
        /// Whether `max` itself is accepted.
        max_included: bool,
    },
}

impl Bounds {
    /// Whole numbers `min..=max`.
    pub const fn whole(min: u64, max: u64) -> Self {
        Self::Whole {
            min,
            max: Some(max),
        }
    }

    /// Whole numbers `>= min`.
    pub const fn whole_at_least(min: u64) -> Self {
        Self::Whole { min, max: None }
    }

    /// Finite reals `>= min`.
    pub const fn at_least(min: f64) -> Self {
        Self::real(min, true, f64::INFINITY, false)
    }

    /// Finite reals `> min`.
    pub const fn above(min: f64) -> Self {
        Self::real(min, false, f64::INFINITY, false)
    }

    /// Finite reals in `[min, max]`.
    pub const fn closed(min: f64, max: f64) -> Self {
        Self::real(min, true, max, true)
    }

    /// Finite reals in `(min, max)`.
    pub const fn open(min: f64, max: f64) -> Self {
        Self::real(min, false, max, false)
    }

    /// Finite reals in `[min, max)`.
    pub const fn half_open(min: f64, max: f64) -> Self {
        Self::real(min, true, max, false)
    }

    /// Any finite real.
    pub const fn finite() -> Self {
        Self::real(f64::NEG_INFINITY, false, f64::INFINITY, false)
    }

    const fn real(min: f64, min_included: bool, max: f64, max_included: bool) -> Self {
        Self::Real {
            min,
            min_included,
            max,
            max_included,
        }
    }

    /// Whether `value` is accepted (a real must also be finite).
    pub fn contains(&self, value: f64) -> bool {
        match *self {
            Self::Whole { min, max } => {
                value.fract() == 0.0
                    && value >= min as f64
                    && max.is_none_or(|max| value <= max as f64)
            }
            Self::Real {
                min,
                min_included,
                max,
                max_included,
            } => {
                value.is_finite()
                    && (value > min || (min_included && value == min))
                    && (value < max || (max_included && value == max))
            }
        }
    }

    /// `Ok` when `value` is accepted, else the message "`field` is VALUE, must be RULE".
    pub fn check(&self, field: &str, value: impl OptionValue) -> Result<(), String> {
        if self.contains(value.as_f64()) {
            Ok(())
        } else {
            Err(format!("{field} is {value}, must be {}", self.rule()))
        }
    }

    /// The rule as an error message says it: "in 1..=64", "finite and > 0", "in [0, 1]".
    fn rule(&self) -> String {
        match (self, self.one_sided()) {
            _ if self.is_interval() => format!("in {self}"),
            (Self::Real { .. }, Some(side)) => format!("finite and {side}"),
            _ => self.to_string(),
        }
    }

    /// Whether the bounds print as an interval (both ends bounded).
    fn is_interval(&self) -> bool {
        match *self {
            Self::Whole { max, .. } => max.is_some(),
            Self::Real { min, max, .. } => min.is_finite() && max.is_finite(),
        }
    }

    /// The one bound of a real with a single finite end: ">= 0", "> 0", "< 90".
    fn one_sided(&self) -> Option<String> {
        match *self {
            Self::Real {
                min,
                min_included,
                max,
                ..
            } if min.is_finite() && !max.is_finite() => {
                Some(format!("{} {min}", if min_included { ">=" } else { ">" }))
            }
            Self::Real {
                max, max_included, ..
            } if max.is_finite() => {
                Some(format!("{} {max}", if max_included { "<=" } else { "<" }))
            }
            _ => None,
        }
    }
}

/// A number an option holds: checked as an `f64`, shown in messages as itself.
pub trait OptionValue: Copy + fmt::Display {
    /// The value as an `f64` (exact for every value a bound can tell apart).
    fn as_f64(self) -> f64;
}

macro_rules! option_values {
    ($($t:ty),*) => {$(
        impl OptionValue for $t {
            fn as_f64(self) -> f64 {
                self as f64
            }
        }
    )*};
}
option_values!(u32, u64, usize, f32, f64);

/// As the C docs print it: `1..=64`, `>= 1`, `[0, 1]`, `(0, 180)`, `finite, > 0`, `finite`.
impl fmt::Display for Bounds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Whole {
                min,
                max: Some(max),
            } => write!(f, "{min}..={max}"),
            Self::Whole { min, max: None } => write!(f, ">= {min}"),
            Self::Real {
                min,
                min_included,
                max,
                max_included,
            } if min.is_finite() && max.is_finite() => write!(
                f,
                "{}{min}, {max}{}",
                if min_included { '[' } else { '(' },
                if max_included { ']' } else { ')' }
            ),
            Self::Real { .. } => match self.one_sided() {
                Some(side) => write!(f, "finite, {side}"),
                None => f.write_str("finite"),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_bounds_accept_their_ends_and_refuse_outside_and_fractions() {
        let b = Bounds::whole(1, 64);
        assert!(b.contains(1.0) && b.contains(64.0));
        assert!(!b.contains(0.0) && !b.contains(65.0) && !b.contains(1.5));
        assert_eq!(b.to_string(), "1..=64");
        assert_eq!(
            b.check("candidates", 65u32).unwrap_err(),
            "candidates is 65, must be in 1..=64"
        );
        let open = Bounds::whole_at_least(6);
        assert!(open.contains(1e12) && !open.contains(5.0));
        assert_eq!(open.to_string(), ">= 6");
        assert_eq!(open.check("n", 5u32).unwrap_err(), "n is 5, must be >= 6");
    }

    #[test]
    fn real_bounds_refuse_non_finite_values_and_excluded_ends() {
        let positive = Bounds::above(0.0);
        assert!(positive.contains(1e-9) && !positive.contains(0.0));
        assert!(!positive.contains(f64::INFINITY) && !positive.contains(f64::NAN));
        assert_eq!(positive.to_string(), "finite, > 0");
        assert_eq!(
            positive.check("temperature", 0.0f32).unwrap_err(),
            "temperature is 0, must be finite and > 0"
        );
        let probability = Bounds::closed(0.0, 1.0);
        assert!(probability.contains(0.0) && probability.contains(1.0));
        assert!(!probability.contains(1.0001));
        assert_eq!(probability.to_string(), "[0, 1]");
        assert_eq!(
            probability.check("p", 2.0).unwrap_err(),
            "p is 2, must be in [0, 1]"
        );
        let angle = Bounds::open(0.0, 180.0);
        assert!(!angle.contains(0.0) && !angle.contains(180.0) && angle.contains(90.0));
        assert_eq!(angle.to_string(), "(0, 180)");
        assert_eq!(Bounds::at_least(0.0).to_string(), "finite, >= 0");
        assert!(Bounds::at_least(0.0).contains(0.0));
        let any = Bounds::finite();
        assert!(any.contains(-1e300) && !any.contains(f64::NEG_INFINITY));
        assert_eq!(any.to_string(), "finite");
        assert_eq!(
            any.check("m", f64::NAN).unwrap_err(),
            "m is NaN, must be finite"
        );
    }
}
