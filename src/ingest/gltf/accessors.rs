//! Accessors checked before they are read: component type, dimensions, normalization and
//! byte range against their buffer views; and values made finite where a file carries NaN.

use super::Importer;
use crate::error::Result;
use gltf::accessor::{DataType, Dimensions};

impl<'a> Importer<'a> {
    /// Checks that `accessor` has an allowed type and that all its bytes exist.
    pub(super) fn check_accessor(
        &self,
        accessor: &gltf::Accessor,
        element: &str,
        dims: &[Dimensions],
        types: &[DataType],
        normalized_integers: bool,
    ) -> Result<()> {
        let e = format!("{element} (accessors[{}])", accessor.index());
        if accessor.count() == 0 {
            return Err(self.err(&e, "accessor has count 0"));
        }
        if !dims.contains(&accessor.dimensions()) || !types.contains(&accessor.data_type()) {
            return Err(self.err(
                &e,
                format!(
                    "accessor is {:?} of {:?}; expected {dims:?} of {types:?}",
                    accessor.dimensions(),
                    accessor.data_type()
                ),
            ));
        }
        if normalized_integers && accessor.data_type() != DataType::F32 && !accessor.normalized() {
            return Err(self.err(&e, "integer accessor must be normalized"));
        }
        let check_range =
            |view: gltf::buffer::View, offset: usize, count: usize, elem: usize| -> Result<()> {
                let stride = view.stride().unwrap_or(elem);
                if count == 0 {
                    return Ok(());
                }
                if stride < elem {
                    return Err(self.err(
                        &e,
                        format!("byteStride {stride} is smaller than the element size {elem}"),
                    ));
                }
                let end = (count - 1)
                    .checked_mul(stride)
                    .and_then(|x| x.checked_add(offset))
                    .and_then(|x| x.checked_add(elem));
                if end.is_none_or(|end| end > view.length()) {
                    return Err(self.err(
                        &e,
                        format!(
                            "accessor data runs past the end of bufferViews[{}]",
                            view.index()
                        ),
                    ));
                }
                let buffer_len = self.buffers.get(view.buffer().index()).map_or(0, Vec::len);
                if view
                    .offset()
                    .checked_add(view.length())
                    .is_none_or(|end| end > buffer_len)
                {
                    return Err(self.err(
                        &e,
                        format!(
                            "bufferViews[{}] runs past the end of its buffer",
                            view.index()
                        ),
                    ));
                }
                Ok(())
            };
        match (accessor.view(), accessor.sparse()) {
            (Some(view), _) => {
                check_range(view, accessor.offset(), accessor.count(), accessor.size())?
            }
            (None, None) => {
                return Err(self.err(
                    &e,
                    "accessor has no data (no bufferView and no sparse values)",
                ));
            }
            (None, Some(_)) => {}
        }
        if let Some(sparse) = accessor.sparse() {
            let indices = sparse.indices();
            check_range(
                indices.view(),
                indices.offset(),
                sparse.count(),
                indices.index_type().size(),
            )?;
            let values = sparse.values();
            check_range(
                values.view(),
                values.offset(),
                sparse.count(),
                accessor.size(),
            )?;
            // Each index names an element of the accessor, in increasing order
            // (glTF-Validator: ACCESSOR_SPARSE_INDEX_OOB, ACCESSOR_SPARSE_INDICES_NON_INCREASING).
            let view = indices.view();
            let size = indices.index_type().size();
            if view.stride().is_some_and(|s| s != size) {
                return Err(self.err(&e, "sparse.indices' bufferView must not have a byteStride"));
            }
            let start = view.offset() + indices.offset();
            let bytes = &self.buffers[view.buffer().index()][start..start + sparse.count() * size];
            let mut previous: Option<usize> = None;
            for (k, chunk) in bytes.chunks_exact(size).enumerate() {
                let index = match size {
                    1 => chunk[0] as usize,
                    2 => u16::from_le_bytes([chunk[0], chunk[1]]) as usize,
                    _ => u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]) as usize,
                };
                if index >= accessor.count() {
                    return Err(self.err(
                        &e,
                        format!(
                            "sparse.indices[{k}] = {index} is past the accessor's {} elements",
                            accessor.count()
                        ),
                    ));
                }
                if previous.is_some_and(|p| index <= p) {
                    return Err(self.err(
                        &e,
                        format!("sparse.indices[{k}] = {index} does not increase"),
                    ));
                }
                previous = Some(index);
            }
        }
        Ok(())
    }
}

/// Collects attribute values, replacing those that fail `ok` by `fallback` and counting them.
pub(super) fn finite_or<T>(
    values: impl Iterator<Item = T>,
    ok: impl Fn(&T) -> bool,
    fallback: T,
    repaired: &mut usize,
) -> Vec<T>
where
    T: Copy,
{
    values
        .map(|v| {
            if ok(&v) {
                v
            } else {
                *repaired += 1;
                fallback
            }
        })
        .collect()
}
