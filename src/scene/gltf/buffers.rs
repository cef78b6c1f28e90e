//! A glTF file's bytes: its buffers (embedded, beside it or in a data URI), and its accessors
//! checked against their views and buffers before they are read, whatever their component
//! type.

use super::*;

/// Component types of attributes that `KHR_mesh_quantization` lets be integers, normalised or
/// not (positions, texture coordinates).
pub(super) const QUANTIZED: &[DataType] = &[
    DataType::F32,
    DataType::I8,
    DataType::U8,
    DataType::I16,
    DataType::U16,
];

/// Component types of attributes that `KHR_mesh_quantization` lets be signed normalised
/// integers (normals, tangents, morph displacements).
pub(super) const SIGNED: &[DataType] = &[DataType::F32, DataType::I8, DataType::I16];

/// An accessor's elements (of two to four components, the rest 0) as floats, whatever its
/// component type: integers mapped to `[0, 1]` or `[-1, 1]` when the accessor is `normalized`
/// (signed ones clamped at -1, as the specification asks), taken as they are otherwise
/// (`KHR_mesh_quantization`). `None` when it cannot be read; the accessor must have been
/// checked ([`Loader::check_accessor`]).
pub(super) fn read_floats<'a, 's, F>(acc: &::gltf::Accessor<'a>, get: F) -> Option<Vec<[f32; 4]>>
where
    F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    use ::gltf::accessor::Iter;
    macro_rules! read {
        ($t:ty, $f:expr) => {{
            let f = $f;
            match acc.dimensions() {
                Dimensions::Vec2 => Iter::<[$t; 2]>::new(acc.clone(), get)?
                    .map(|a| [f(a[0]), f(a[1]), 0.0, 0.0])
                    .collect(),
                Dimensions::Vec3 => Iter::<[$t; 3]>::new(acc.clone(), get)?
                    .map(|a| [f(a[0]), f(a[1]), f(a[2]), 0.0])
                    .collect(),
                Dimensions::Vec4 => Iter::<[$t; 4]>::new(acc.clone(), get)?
                    .map(|a| a.map(f))
                    .collect(),
                _ => return None,
            }
        }};
    }
    // An integer `c` of largest value `max`, normalised or not.
    let norm = acc.normalized();
    let int = move |c: f32, max: f32| if norm { (c / max).max(-1.0) } else { c };
    Some(match acc.data_type() {
        DataType::F32 => read!(f32, |c: f32| c),
        DataType::I8 => read!(i8, |c: i8| int(f32::from(c), 127.0)),
        DataType::U8 => read!(u8, |c: u8| int(f32::from(c), 255.0)),
        DataType::I16 => read!(i16, |c: i16| int(f32::from(c), 32767.0)),
        DataType::U16 => read!(u16, |c: u16| int(f32::from(c), 65535.0)),
        DataType::U32 => return None,
    })
}

/// A buffer's bytes, or why they cannot be had (reported when an accessor needs them).
pub(super) fn load_buffer(
    name: &str,
    b: &::gltf::Buffer,
    blob: Option<&[u8]>,
    read: &dyn Fn(&Path) -> Result<Vec<u8>>,
) -> Buffer {
    let i = b.index();
    if meshopt::is_fallback(b) {
        return Err(format!(
            "{name}: buffers[{i}]: the uncompressed fallback of the meshopt compression, which the file leaves out"
        ));
    }
    let data = match b.source() {
        ::gltf::buffer::Source::Bin => match blob {
            Some(d) => d.to_vec(),
            None => {
                return Err(format!(
                    "{name}: buffers[{i}]: the file has no binary chunk"
                ));
            }
        },
        ::gltf::buffer::Source::Uri(uri) => {
            uri_bytes(uri, read).map_err(|e| format!("{name}: buffers[{i}]: {e:#}"))?
        }
    };
    if data.len() < b.length() {
        return Err(format!(
            "{name}: buffers[{i}]: holds {} bytes, its byteLength says {}",
            data.len(),
            b.length()
        ));
    }
    Ok(data)
}

/// The bytes a URI names: a `data:` URI decoded, or a file beside the glTF (percent-decoded).
pub(super) fn uri_bytes(uri: &str, read: &dyn Fn(&Path) -> Result<Vec<u8>>) -> Result<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((_, payload)) = rest.split_once(";base64,") else {
            bail!("data URI is not base64");
        };
        return base64::engine::general_purpose::STANDARD
            .decode(payload.trim())
            .map_err(|e| anyhow!("data URI: bad base64: {e}"));
    }
    if uri.contains("://") {
        bail!("{uri}: only files beside the glTF and data URIs are read");
    }
    let file = percent_encoding::percent_decode_str(uri).decode_utf8_lossy();
    read(Path::new(file.as_ref()))
}

impl Loader<'_> {
    /// A vertex attribute's values when there is one per vertex; otherwise `None`, with a
    /// warning saying what is done instead.
    pub(super) fn per_vertex<T>(
        &mut self,
        at: &str,
        what: &str,
        values: Option<Vec<T>>,
        n: usize,
        instead: &str,
    ) -> Option<Vec<T>> {
        let values = values.unwrap_or_default();
        if values.len() == n {
            return Some(values);
        }
        self.warnings.push(format!(
            "{at}: {what} has {} entries for {n} vertices; {instead}",
            values.len()
        ));
        None
    }

    /// Checks that an accessor can be read as `dims` of one of `types`, and that every byte it
    /// covers lies inside its buffer view and buffer.
    pub(super) fn check_accessor(
        &self,
        at: &str,
        what: &str,
        acc: &::gltf::Accessor,
        types: &[DataType],
        dims: Dimensions,
    ) -> Result<()> {
        let i = acc.index();
        let at = format!("{at}: {what} (accessors[{i}])");
        if !types.contains(&acc.data_type()) || acc.dimensions() != dims {
            bail!(
                "{at}: {:?} {:?}, expected {dims:?} of {types:?}",
                acc.dimensions(),
                acc.data_type()
            );
        }
        let count = acc.count();
        if count == 0 {
            bail!("{at}: no elements");
        }
        let size = acc.size();
        match acc.view() {
            Some(view) => {
                self.check_span(&at, "elements", &view, acc.offset(), count, size)?;
            }
            // Without a bufferView the elements are zeros, which a sparse accessor replaces
            // in part.
            None if acc.sparse().is_some() => {}
            None => bail!("{at}: no bufferView"),
        }
        if let Some(sparse) = acc.sparse() {
            self.check_sparse(&at, &sparse, count, size)?;
        }
        Ok(())
    }

    /// Checks that `count` elements of `size` bytes from byte `offset` of `view` (at its stride)
    /// lie inside it, and it inside its buffer; `what` names them in the message.
    pub(super) fn check_span(
        &self,
        at: &str,
        what: &str,
        view: &::gltf::buffer::View,
        offset: usize,
        count: usize,
        size: usize,
    ) -> Result<&[u8]> {
        let stride = view.stride().unwrap_or(size);
        if stride < size {
            bail!("{at}: byteStride {stride} is smaller than an element ({size} bytes)");
        }
        let span = count
            .checked_sub(1)
            .and_then(|c| c.checked_mul(stride))
            .and_then(|s| s.checked_add(size))
            .and_then(|s| s.checked_add(offset));
        match span {
            Some(end) if end <= view.length() => {}
            _ => bail!(
                "{at}: {count} {what} from byte {offset} (stride {stride}) run past bufferViews[{}] ({} bytes)",
                view.index(),
                view.length()
            ),
        }
        let b = view.buffer().index();
        let data = match self.buffers.get(b) {
            Some(Ok(d)) => d,
            Some(Err(why)) => bail!("{why}"),
            None => bail!("{at}: buffers[{b}] does not exist"),
        };
        match view.offset().checked_add(view.length()) {
            Some(end) if end <= data.len() => Ok(&data[view.offset()..end]),
            _ => bail!(
                "{at}: bufferViews[{}] (bytes {}..+{}) runs past buffers[{b}] ({} bytes)",
                view.index(),
                view.offset(),
                view.length(),
                data.len()
            ),
        }
    }

    /// Checks a sparse accessor's substitutions into `count` elements of `size` bytes: their
    /// indices and values lie inside their views, and the indices rise strictly and stay below
    /// `count`, as the specification asks (a reader applies them in one pass, so any other
    /// order would silently drop some).
    pub(super) fn check_sparse(
        &self,
        at: &str,
        sparse: &::gltf::accessor::sparse::Sparse,
        count: usize,
        size: usize,
    ) -> Result<()> {
        use ::gltf::accessor::sparse::IndexType;
        let n = sparse.count();
        if n == 0 || n > count {
            bail!("{at}: sparse count {n} is not between 1 and the accessor's count {count}");
        }
        let values = sparse.values();
        self.check_span(
            at,
            "sparse values",
            &values.view(),
            values.offset(),
            n,
            size,
        )?;
        let indices = sparse.indices();
        let width = match indices.index_type() {
            IndexType::U8 => 1,
            IndexType::U16 => 2,
            IndexType::U32 => 4,
        };
        let view = indices.view();
        let offset = indices.offset();
        let bytes = self.check_span(at, "sparse indices", &view, offset, n, width)?;
        let stride = view.stride().unwrap_or(width);
        let mut previous: Option<u32> = None;
        for k in 0..n {
            let b = &bytes[offset + k * stride..][..width];
            let i = match width {
                1 => b[0] as u32,
                2 => u16::from_le_bytes([b[0], b[1]]) as u32,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            };
            if i as usize >= count {
                bail!("{at}: sparse index {i} (entry {k}) is past the accessor's {count} elements");
            }
            if previous.is_some_and(|p| i <= p) {
                bail!(
                    "{at}: sparse indices do not rise strictly (entry {k}: {i} after {})",
                    previous.unwrap_or(0)
                );
            }
            previous = Some(i);
        }
        Ok(())
    }

    /// The encoded bytes of an image: a buffer view or a URI.
    pub(super) fn image_bytes(&self, image: &::gltf::Image) -> Result<Vec<u8>> {
        match image.source() {
            ::gltf::image::Source::View { view, .. } => {
                let b = view.buffer().index();
                let data = match self.buffers.get(b) {
                    Some(Ok(d)) => d,
                    Some(Err(why)) => bail!("{why}"),
                    None => bail!("buffers[{b}] does not exist"),
                };
                view.offset()
                    .checked_add(view.length())
                    .and_then(|end| data.get(view.offset()..end))
                    .map(<[u8]>::to_vec)
                    .ok_or_else(|| anyhow!("bufferViews[{}] runs past buffers[{b}]", view.index()))
            }
            ::gltf::image::Source::Uri { uri, .. } => uri_bytes(uri, self.read),
        }
    }
}
