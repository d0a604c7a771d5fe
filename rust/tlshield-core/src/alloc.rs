//! Allocations whose size comes from a caller (a batch's row count, a monitor count, a copy of
//! an array), made through `try_reserve`: a size the allocator cannot grant is an
//! [`InputError::TooLarge`] naming the argument, never the process abort of `vec![x; n]`.

use crate::error::InputError;

/// `len` copies of `value`, or [`InputError::TooLarge`] naming `what`.
pub fn try_vec<T: Clone>(what: &str, len: usize, value: T) -> Result<Vec<T>, InputError> {
    let mut out = Vec::new();
    try_resize(&mut out, what, len, value)?;
    Ok(out)
}

/// An empty vector with room for `len` items, or [`InputError::TooLarge`] naming `what`.
pub fn try_with_capacity<T>(what: &str, len: usize) -> Result<Vec<T>, InputError> {
    let mut out = Vec::new();
    out.try_reserve_exact(len)
        .map_err(|_| too_large::<T>(what, len))?;
    Ok(out)
}

/// Resizes `v` to `len` items (new ones `value`), reserving first: on failure `v` is unchanged.
pub fn try_resize<T: Clone>(
    v: &mut Vec<T>,
    what: &str,
    len: usize,
    value: T,
) -> Result<(), InputError> {
    if len > v.len() {
        v.try_reserve_exact(len - v.len())
            .map_err(|_| too_large::<T>(what, len))?;
    }
    v.resize(len, value);
    Ok(())
}

/// The product of `dims` (a batch's rows times columns), or [`InputError::TooLarge`] when it
/// overflows `usize`.
pub fn checked_len(what: &str, dims: &[usize]) -> Result<usize, InputError> {
    dims.iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| InputError::TooLarge {
            what: what.to_string(),
            count: dims
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(" x "),
            bytes: None,
        })
}

/// The error for `len` items of `T` that could not be allocated.
fn too_large<T>(what: &str, len: usize) -> InputError {
    InputError::TooLarge {
        what: what.to_string(),
        count: len.to_string(),
        bytes: len.checked_mul(std::mem::size_of::<T>().max(1)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_size_the_allocator_refuses_is_an_error_naming_it() {
        let err = try_vec("num", usize::MAX / 8, 0.0f64).unwrap_err();
        assert!(matches!(&err, InputError::TooLarge { what, .. } if what == "num"));
        assert!(err.to_string().starts_with("num: "), "{err}");
        let err = try_with_capacity::<[f64; 4]>("rows", 1 << 60).unwrap_err();
        assert!(err.to_string().contains("rows"), "{err}");
    }

    #[test]
    fn a_failed_resize_leaves_the_vector_as_it_was() {
        let mut v = vec![1.0f64; 3];
        crate::tests_support::assert_error(
            try_resize(&mut v, "rows", usize::MAX / 16, 0.0),
            "TooLarge",
            "rows",
        );
        assert_eq!(v, vec![1.0; 3]);
        try_resize(&mut v, "rows", 5, 2.0).unwrap();
        assert_eq!(v, vec![1.0, 1.0, 1.0, 2.0, 2.0]);
        try_resize(&mut v, "rows", 0, 2.0).unwrap();
        assert!(v.is_empty());
    }

    #[test]
    fn products_that_overflow_are_refused() {
        assert_eq!(checked_len("states", &[0, usize::MAX]).unwrap(), 0);
        assert_eq!(checked_len("states", &[3, 4]).unwrap(), 12);
        let err = checked_len("states", &[1 << 62, 8]).unwrap_err();
        assert!(err.to_string().contains("4611686018427387904 x 8"), "{err}");
    }

    #[test]
    fn bytes_read_as_people_write_them() {
        let err = |bytes| InputError::TooLarge {
            what: "rows".into(),
            count: "2".into(),
            bytes,
        };
        assert!(err(Some(12)).to_string().ends_with("(12 bytes requested)"));
        assert!(err(Some(16 << 40))
            .to_string()
            .ends_with("(16.0 TiB requested)"));
        assert!(err(None).to_string().ends_with("(their size overflows)"));
    }
}
