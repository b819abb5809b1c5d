//! How a boundary struct copies a library struct: [`Mirror`] converts field by field, and
//! `mirror!` declares a `Serialize` struct with the library struct's fields whose conversion
//! destructures the source exhaustively, so a field added, removed or renamed there fails to
//! compile here until its key is placed in the schema.

use std::collections::BTreeMap;

/// `Self` is the `--stats` form of `T`.
pub(crate) trait Mirror<T: ?Sized> {
    fn mirror(value: &T) -> Self;
}

/// Plain values are their own `--stats` form.
macro_rules! mirror_as_is {
    ($($t:ty),* $(,)?) => {
        $(impl Mirror<$t> for $t {
            fn mirror(value: &$t) -> Self {
                value.clone()
            }
        })*
    };
}

mirror_as_is!(
    bool,
    u32,
    u64,
    usize,
    f32,
    f64,
    &'static str,
    String,
    [u32; 3]
);

impl<T, U: Mirror<T>> Mirror<Option<T>> for Option<U> {
    fn mirror(value: &Option<T>) -> Self {
        value.as_ref().map(U::mirror)
    }
}

impl<T, U: Mirror<T>> Mirror<Vec<T>> for Vec<U> {
    fn mirror(value: &Vec<T>) -> Self {
        value.iter().map(U::mirror).collect()
    }
}

/// A map keyed by a library enum: its keys are the enum's names (`Display`).
impl<K: std::fmt::Display, T, U: Mirror<T>> Mirror<BTreeMap<K, T>> for BTreeMap<String, U> {
    fn mirror(value: &BTreeMap<K, T>) -> Self {
        value
            .iter()
            .map(|(k, v)| (k.to_string(), U::mirror(v)))
            .collect()
    }
}

/// `mirror! { /// doc
///     Name from path::to::Source { field: Type, #[serde(...)] other: Type } }`
/// declares `pub struct Name` (`Serialize`) with `From<&Source>`; each field converts with
/// [`Mirror`]. List every field of `Source`: the conversion names them all.
macro_rules! mirror {
    (
        $(#[$meta:meta])*
        $name:ident from $($src:ident)::+ {
            $( $(#[$fmeta:meta])* $field:ident: $ty:ty ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Debug, PartialEq, serde::Serialize)]
        pub struct $name {
            $( $(#[$fmeta])* pub $field: $ty, )*
        }

        impl $crate::stats::mirror::Mirror<$($src)::+> for $name {
            fn mirror(value: &$($src)::+) -> Self {
                let $($src)::+ { $($field),* } = value;
                Self {
                    $( $field: $crate::stats::mirror::Mirror::mirror($field), )*
                }
            }
        }

        impl From<&$($src)::+> for $name {
            fn from(value: &$($src)::+) -> Self {
                $crate::stats::mirror::Mirror::mirror(value)
            }
        }
    };
}

pub(crate) use mirror;
