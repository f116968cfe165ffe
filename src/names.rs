//! The names users type for the library's choices — `--transfer blend-idw`, `--inside flood`,
//! `--solver multilevel`, `--outside keep`, `--loose-parts rest` — written once, here. The
//! command line's options, the Python package's arguments (and its messages, which say a
//! flag and its choice as a keyword argument) and the editor's `deform` flags read them
//! through [`FromStr`] and write them through [`Display`](fmt::Display), so the faces cannot
//! disagree on a name.
//!
//! Each choice gets its table from `named!`: the values in the order help texts list them,
//! each with its name, and an exhaustive `match`, so a new value without a name does not
//! compile.

use std::fmt;
use std::str::FromStr;

use crate::cells::Inside;
use crate::field::{Outside, Transfer};
use crate::solve::{LooseParts, Method};

/// A choice whose values have names.
pub trait Named: Copy + PartialEq + 'static {
    /// What the choice is, in messages: `transfer`.
    const WHAT: &'static str;
    /// Every value, in the order help texts list them.
    const ALL: &'static [Self];

    /// The value's name.
    fn name(self) -> &'static str;

    /// The value named `name` (exactly: names are lower case).
    fn from_name(name: &str) -> Result<Self, UnknownName> {
        Self::ALL
            .iter()
            .copied()
            .find(|v| v.name() == name)
            .ok_or_else(|| UnknownName {
                what: Self::WHAT,
                name: name.to_owned(),
                expected: Self::ALL.iter().map(|v| v.name()).collect(),
            })
    }
}

/// A name that names none of a choice's values.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownName {
    /// What the choice is ([`Named::WHAT`]).
    pub what: &'static str,
    /// The name given.
    pub name: String,
    /// The names of the choice's values, in order.
    pub expected: Vec<&'static str>,
}

impl fmt::Display for UnknownName {
    /// `transfer `bogus`: expected blend, blend-idw, rbf or pu`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} `{}`: expected {}",
            self.what,
            self.name,
            listing(&self.expected)
        )
    }
}

impl std::error::Error for UnknownName {}

/// Names as a sentence lists them: `a`, `a or b`, `a, b or c`.
pub fn listing(names: &[&str]) -> String {
    match names {
        [] => String::new(),
        [one] => (*one).to_owned(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
    }
}

/// Implements [`Named`], [`Display`](fmt::Display) and [`FromStr`] for the enum `$ty` from its
/// table of `Variant => "name"`.
macro_rules! named {
    ($ty:ident, $what:literal, { $($variant:ident => $name:literal),+ $(,)? }) => {
        impl Named for $ty {
            const WHAT: &'static str = $what;
            const ALL: &'static [Self] = &[$($ty::$variant),+];

            fn name(self) -> &'static str {
                match self {
                    $($ty::$variant => $name),+
                }
            }
        }

        impl fmt::Display for $ty {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.pad(self.name())
            }
        }

        impl FromStr for $ty {
            type Err = UnknownName;

            fn from_str(name: &str) -> Result<Self, UnknownName> {
                Self::from_name(name)
            }
        }
    };
}

named!(Transfer, "transfer", {
    Blend => "blend",
    BlendIdw => "blend-idw",
    Rbf => "rbf",
    Pu => "pu",
});

named!(Inside, "inside", {
    Auto => "auto",
    Winding => "winding",
    Flood => "flood",
    None => "none",
});

named!(Method, "solver", {
    Auto => "auto",
    Direct => "direct",
    Multilevel => "multilevel",
    LocalGlobal => "local-global",
});

named!(Outside, "outside", {
    Refuse => "refuse",
    Keep => "keep",
    Extend => "extend",
});

named!(LooseParts, "loose parts", {
    Carry => "carry",
    Rest => "rest",
});

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip<T: Named + fmt::Display + FromStr<Err = UnknownName> + fmt::Debug>() {
        for &v in T::ALL {
            assert_eq!(v.to_string(), v.name());
            assert_eq!(v.name().parse::<T>(), Ok(v));
        }
        let names: Vec<_> = T::ALL.iter().map(|v| v.name()).collect();
        let mut unique = names.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "{names:?}");
    }

    #[test]
    fn every_name_reads_back_as_its_value() {
        round_trip::<Transfer>();
        round_trip::<Inside>();
        round_trip::<Method>();
        round_trip::<Outside>();
        round_trip::<LooseParts>();
    }

    #[test]
    fn an_unknown_name_lists_the_known_ones() {
        let e = "Pu".parse::<Transfer>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "transfer `Pu`: expected blend, blend-idw, rbf or pu"
        );
        let e = "x".parse::<Outside>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "outside `x`: expected refuse, keep or extend"
        );
        assert_eq!(listing(&["a"]), "a");
        assert_eq!(listing(&["a", "b"]), "a or b");
    }
}
