//! Fixed-length arrays read from scene files that refuse extra elements. serde's `[T; N]`
//! takes the first `N` elements of a longer TOML array and drops the rest, so a 4-component
//! axis or a 5-column matrix row would load trimmed; pbrt-v4 makes such input fatal, and so
//! does striae: every fixed-length array of the scene format is read through [`Exact`].

use serde::de::{self, Deserialize, Deserializer, IgnoredAny, SeqAccess, Visitor};
use std::fmt;
use std::marker::PhantomData;

/// `[T; N]` that deserialises only from an array of exactly `N` elements.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exact<T, const N: usize>(pub [T; N]);

impl<'de, T: Deserialize<'de>, const N: usize> Deserialize<'de> for Exact<T, N> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct ExactVisitor<T, const N: usize>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>, const N: usize> Visitor<'de> for ExactVisitor<T, N> {
            type Value = Exact<T, N>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                write!(f, "an array of exactly {N} elements")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let mut items = Vec::with_capacity(N);
                while items.len() < N {
                    match seq.next_element::<T>()? {
                        Some(item) => items.push(item),
                        None => return Err(de::Error::invalid_length(items.len(), &self)),
                    }
                }
                let mut len = N;
                while seq.next_element::<IgnoredAny>()?.is_some() {
                    len += 1;
                }
                if len > N {
                    return Err(de::Error::invalid_length(len, &self));
                }
                match items.try_into() {
                    Ok(array) => Ok(Exact(array)),
                    Err(_) => unreachable!("exactly N items were collected"),
                }
            }
        }
        deserializer.deserialize_seq(ExactVisitor(PhantomData))
    }
}

/// `#[serde(deserialize_with = "strict_array::exact")]` for a `[T; N]` field.
pub fn exact<'de, D, T, const N: usize>(deserializer: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Exact::<T, N>::deserialize(deserializer).map(|e| e.0)
}

/// `#[serde(default, deserialize_with = "strict_array::optional")]` for an `Option<[T; N]>`.
pub fn optional<'de, D, T, const N: usize>(deserializer: D) -> Result<Option<[T; N]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<Exact<T, N>>::deserialize(deserializer).map(|o| o.map(|e| e.0))
}

/// A row-major `N x N` matrix whose rows are all exactly `N` long.
pub fn matrix<'de, D, const N: usize>(deserializer: D) -> Result<[[f32; N]; N], D::Error>
where
    D: Deserializer<'de>,
{
    let rows = Exact::<Exact<f32, N>, N>::deserialize(deserializer)?;
    Ok(rows.0.map(|row| row.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    struct S {
        #[serde(deserialize_with = "exact")]
        v: [f32; 3],
        #[serde(default, deserialize_with = "optional")]
        o: Option<[f32; 3]>,
        #[serde(default, deserialize_with = "matrix")]
        m: [[f32; 2]; 2],
    }

    #[test]
    fn only_the_exact_length_is_accepted() {
        let s: S = toml::from_str("v = [1, 2, 3]\no = [4, 5, 6]\nm = [[1, 0], [0, 1]]").unwrap();
        assert_eq!(
            (s.v, s.o, s.m),
            (
                [1.0, 2.0, 3.0],
                Some([4.0, 5.0, 6.0]),
                [[1.0, 0.0], [0.0, 1.0]]
            )
        );
        assert_eq!(toml::from_str::<S>("v = [1, 2, 3]").unwrap().o, None);
        for (text, len) in [
            ("v = [1, 2, 3, 4]", "4"),
            ("v = [1, 2]", "2"),
            ("v = [1, 2, 3]\no = [1, 2, 3, 4, 5]", "5"),
            ("v = [1, 2, 3]\nm = [[1, 0, 9], [0, 1]]", "3"),
            ("v = [1, 2, 3]\nm = [[1, 0], [0, 1], [0, 0]]", "3"),
        ] {
            let e = toml::from_str::<S>(text).unwrap_err().to_string();
            assert!(
                e.contains(&format!(
                    "invalid length {len}, expected an array of exactly"
                )),
                "{text}: {e}"
            );
        }
    }
}
