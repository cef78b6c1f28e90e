//! A glTF mesh primitive's vertices and triangles: its attributes read (quantised or not),
//! its morph targets applied at the node's weights, its skin's influences, its index list by
//! mode.

use super::*;

impl Loader<'_> {
    /// Reads a primitive's vertices and triangles (its morph targets at `weights`, its joints
    /// and weights when `skinned`), or `None` when it is left out (with the reason counted for
    /// the warnings).
    pub(super) fn read_primitive(
        &mut self,
        mesh: usize,
        prim: &::gltf::Primitive,
        weights: &[f32],
        skinned: bool,
    ) -> Result<Option<Primitive>> {
        let at = format!("{}: meshes[{mesh}].primitives[{}]", self.name, prim.index());
        let mode = prim.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            *self.left_out.entry(format!("{mode:?}")).or_default() += 1;
            return Ok(None);
        }
        let Some(pos_acc) = prim.get(&::gltf::Semantic::Positions) else {
            *self.left_out.entry("without POSITION".into()).or_default() += 1;
            return Ok(None);
        };
        self.check_accessor(&at, "POSITION", &pos_acc, QUANTIZED, Dimensions::Vec3)?;
        let buffers = self.buffers;
        let get = |b: ::gltf::Buffer| buffers.get(b.index()).and_then(|d| d.as_deref().ok());
        let reader = prim.reader(get);
        let positions: Vec<Vec3> = read_floats(&pos_acc, get)
            .ok_or_else(|| anyhow!("{at}: POSITION cannot be read"))?
            .into_iter()
            .map(|v| Vec4::from(v).truncate())
            .collect();
        let n = positions.len();

        let normals = match prim.get(&::gltf::Semantic::Normals) {
            Some(acc) => {
                self.check_accessor(&at, "NORMAL", &acc, SIGNED, Dimensions::Vec3)?;
                let normals = read_floats(&acc, get)
                    .map(|r| r.into_iter().map(|v| Vec4::from(v).truncate()).collect());
                self.per_vertex(&at, "NORMAL", normals, n, "flat normals used")
            }
            None => None,
        };
        let material = self.material(prim.material())?;
        let [uvs, uvs1] = self.texcoords(&at, prim, get, material, n)?;
        let normal_mapped = self.materials[material as usize].has_normal_map();
        let tangents = match prim.get(&::gltf::Semantic::Tangents) {
            Some(acc) if normal_mapped => {
                self.check_accessor(&at, "TANGENT", &acc, SIGNED, Dimensions::Vec4)?;
                let tangents =
                    read_floats(&acc, get).map(|r| r.into_iter().map(Vec4::from).collect());
                self.per_vertex(&at, "TANGENT", tangents, n, "MikkTSpace's used")
            }
            _ => None,
        };

        let mut positions = positions;
        let (mut normals, mut tangents) = (normals, tangents);
        self.morph(
            &at,
            prim,
            get,
            weights,
            &mut positions,
            &mut normals,
            &mut tangents,
        )?;
        // Joints and weights only where a skin places the primitive (elsewhere they are unused
        // and not checked).
        let influences = if skinned {
            self.influences(&at, prim, &reader, n)?
        } else {
            None
        };

        let triangles = self.triangles(&at, prim, mode, &reader, &positions)?;
        self.any_uvs |= uvs.is_some();
        self.any_uvs1 |= uvs1.is_some();
        let corner_normals = match (&normals, self.rule) {
            (None, Some(rule)) => Some(crate::scene::normals::corner_normals(
                &positions,
                &triangles,
                rule,
                &[],
            )),
            _ => None,
        };
        Ok(Some(Primitive {
            positions,
            normals,
            corner_normals,
            uvs,
            uvs1,
            tangents,
            influences,
            triangles,
            material,
        }))
    }

    /// The primitive's `TEXCOORD_0`, and its `TEXCOORD_1` where a texture of its material
    /// (`material`) reads it, each of its `n` vertices.
    fn texcoords<'a, 's, F>(
        &mut self,
        at: &str,
        prim: &::gltf::Primitive<'a>,
        get: F,
        material: u32,
        n: usize,
    ) -> Result<[Option<Vec<Vec2>>; 2]>
    where
        F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
    {
        let mut uvs = [None, None];
        for set in 0..2 {
            let reads = |m: &Material| m.textures().any(|t| t.uv_set == set);
            if set > 0 && !reads(&self.materials[material as usize]) {
                continue;
            }
            let what = format!("TEXCOORD_{set}");
            uvs[set as usize] = match prim.get(&::gltf::Semantic::TexCoords(set.into())) {
                Some(acc) => {
                    self.check_accessor(at, &what, &acc, QUANTIZED, Dimensions::Vec2)?;
                    let uvs = read_floats(&acc, get.clone()).map(|r| {
                        r.into_iter()
                            .map(|v| Vec4::from(v).truncate().truncate())
                            .collect()
                    });
                    self.per_vertex(at, &what, uvs, n, "ignored")
                }
                None if set > 0 => {
                    self.warnings.push(format!(
                        "{at}: a texture of its material reads {what}, which it does not have; (0, 0) is read"
                    ));
                    None
                }
                None => None,
            };
        }
        Ok(uvs)
    }

    /// The primitive's triangles by its `mode`: of its indices (each checked against its
    /// vertices), or of its vertices in order; those with a non-finite vertex of `positions`
    /// left out, with a warning.
    fn triangles<'a, 's, F>(
        &mut self,
        at: &str,
        prim: &::gltf::Primitive<'a>,
        mode: Mode,
        reader: &::gltf::mesh::Reader<'a, 's, F>,
        positions: &[Vec3],
    ) -> Result<Vec<[u32; 3]>>
    where
        F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
    {
        let n = positions.len();
        let indices: Vec<u32> = match prim.indices() {
            Some(acc) => {
                self.check_accessor(
                    at,
                    "indices",
                    &acc,
                    &[DataType::U8, DataType::U16, DataType::U32],
                    Dimensions::Scalar,
                )?;
                let indices: Vec<u32> = reader
                    .read_indices()
                    .ok_or_else(|| anyhow!("{at}: indices cannot be read"))?
                    .into_u32()
                    .collect();
                if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
                    bail!("{at}: index {bad} out of range ({n} vertices)");
                }
                indices
            }
            None => (0..n as u32).collect(),
        };
        let triangles = triangles_of(mode, &indices);
        if mode == Mode::Triangles && !indices.len().is_multiple_of(3) {
            self.warnings.push(format!(
                "{at}: {} {} is not a multiple of 3; the last {} left out",
                indices.len(),
                if prim.indices().is_some() {
                    "indices"
                } else {
                    "vertices"
                },
                indices.len() % 3
            ));
        }

        // Triangles with a non-finite vertex have no surface: left out, and said.
        let finite: Vec<bool> = positions.iter().map(|p| p.is_finite()).collect();
        let before = triangles.len();
        let triangles: Vec<[u32; 3]> = triangles
            .into_iter()
            .filter(|t| t.iter().all(|&i| finite[i as usize]))
            .collect();
        if triangles.len() < before {
            self.warnings.push(format!(
                "{at}: {} triangle(s) with a non-finite vertex left out",
                before - triangles.len()
            ));
        }
        Ok(triangles)
    }

    /// Adds a primitive's morph targets at `weights` to its positions, normals and tangents
    /// (every displacement accessor checked first, a count other than the vertex count an
    /// error; a weight the mesh lacks is 0, with a warning).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn morph<'a, 's, F>(
        &mut self,
        at: &str,
        prim: &::gltf::Primitive<'a>,
        get: F,
        weights: &[f32],
        positions: &mut [Vec3],
        normals: &mut Option<Vec<Vec3>>,
        tangents: &mut Option<Vec<Vec4>>,
    ) -> Result<()>
    where
        F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
    {
        let targets: Vec<_> = prim.morph_targets().collect();
        if targets.is_empty() {
            return Ok(());
        }
        // No weights at all means every weight 0 (the specification's default).
        if !weights.is_empty() && weights.len() != targets.len() {
            self.warnings.push(format!(
                "{at}: {} morph target(s) and {} weight(s); a missing weight is 0",
                targets.len(),
                weights.len()
            ));
        }
        for (k, t) in targets.iter().enumerate() {
            for (attr, acc) in [
                ("POSITION", t.positions()),
                ("NORMAL", t.normals()),
                ("TANGENT", t.tangents()),
            ] {
                if let Some(acc) = acc {
                    let what = format!("targets[{k}].{attr}");
                    self.check_accessor(at, &what, &acc, SIGNED, Dimensions::Vec3)?;
                }
            }
        }
        let n = positions.len();
        for (k, t) in targets.iter().enumerate() {
            let w = weights.get(k).copied().unwrap_or(0.0);
            if !w.is_finite() {
                self.warnings.push(format!(
                    "{at}: morph weight {k} is {w}; the target is left out"
                ));
                continue;
            }
            if w == 0.0 {
                continue;
            }
            let read =
                |attr: &str, acc: Option<::gltf::Accessor<'a>>| -> Result<Option<Vec<Vec3>>> {
                    let Some(acc) = acc else {
                        return Ok(None);
                    };
                    let d = read_floats(&acc, get.clone())
                        .ok_or_else(|| anyhow!("{at}: targets[{k}].{attr} cannot be read"))?;
                    if d.len() != n {
                        bail!(
                            "{at}: targets[{k}].{attr} has {} elements for {n} vertices",
                            d.len()
                        );
                    }
                    Ok(Some(
                        d.into_iter().map(|v| Vec4::from(v).truncate()).collect(),
                    ))
                };
            if let Some(d) = read("POSITION", t.positions())? {
                for (p, d) in positions.iter_mut().zip(d) {
                    *p += w * d;
                }
            }
            if let (Some(d), Some(ns)) = (read("NORMAL", t.normals())?, normals.as_mut()) {
                for (v, d) in ns.iter_mut().zip(d) {
                    *v += w * d;
                }
            }
            if let (Some(d), Some(ts)) = (read("TANGENT", t.tangents())?, tangents.as_mut()) {
                for (v, d) in ts.iter_mut().zip(d) {
                    *v += (w * d).extend(0.0);
                }
            }
        }
        Ok(())
    }

    /// Each vertex's joints and weights (`JOINTS_n` with `WEIGHTS_n`, every set there is), or
    /// `None` when the primitive has no `JOINTS_0`.
    pub(super) fn influences<'a, 's, F>(
        &mut self,
        at: &str,
        prim: &::gltf::Primitive<'a>,
        reader: &::gltf::mesh::Reader<'a, 's, F>,
        n: usize,
    ) -> Result<Option<Influences>>
    where
        F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
    {
        use ::gltf::Semantic;
        let mut out: Option<Influences> = None;
        for set in 0..MAX_INFLUENCE_SETS {
            let (joints, weights) = (
                prim.get(&Semantic::Joints(set)),
                prim.get(&Semantic::Weights(set)),
            );
            let (Some(j), Some(w)) = (joints.clone(), weights.clone()) else {
                if joints.is_some() != weights.is_some() {
                    bail!("{at}: JOINTS_{set} and WEIGHTS_{set} come in pairs; one is missing");
                }
                break;
            };
            let (jw, ww) = (format!("JOINTS_{set}"), format!("WEIGHTS_{set}"));
            let ints = [DataType::U8, DataType::U16];
            self.check_accessor(at, &jw, &j, &ints, Dimensions::Vec4)?;
            let floats = [DataType::F32, DataType::U8, DataType::U16];
            self.check_accessor(at, &ww, &w, &floats, Dimensions::Vec4)?;
            let joints: Vec<[u16; 4]> = reader
                .read_joints(set)
                .ok_or_else(|| anyhow!("{at}: {jw} cannot be read"))?
                .into_u16()
                .collect();
            let weights: Vec<[f32; 4]> = reader
                .read_weights(set)
                .ok_or_else(|| anyhow!("{at}: {ww} cannot be read"))?
                .into_f32()
                .collect();
            if joints.len() != n || weights.len() != n {
                bail!(
                    "{at}: {jw} and {ww} have {} and {} elements for {n} vertices",
                    joints.len(),
                    weights.len()
                );
            }
            let out = out.get_or_insert_with(|| vec![Vec::new(); n]);
            for ((o, j), w) in out.iter_mut().zip(&joints).zip(&weights) {
                o.extend(
                    j.iter()
                        .zip(w)
                        .filter(|(_, w)| **w != 0.0)
                        .map(|(j, w)| (*j, *w)),
                );
            }
        }
        Ok(out)
    }
}

/// Triangles of a primitive's index list by its mode (strips alternate their winding so every
/// triangle faces the same way; degenerate ones, with a repeated index, are kept: the BVH
/// leaves zero-area triangles out).
pub(super) fn triangles_of(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::Triangles => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        Mode::TriangleStrip => (2..idx.len())
            .map(|i| {
                if i % 2 == 0 {
                    [idx[i - 2], idx[i - 1], idx[i]]
                } else {
                    [idx[i - 1], idx[i - 2], idx[i]]
                }
            })
            .collect(),
        Mode::TriangleFan => (2..idx.len())
            .map(|i| [idx[0], idx[i - 1], idx[i]])
            .collect(),
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_keep_one_winding_and_fans_turn_about_the_first_vertex() {
        assert_eq!(
            triangles_of(Mode::TriangleStrip, &[0, 1, 2, 3]),
            vec![[0, 1, 2], [2, 1, 3]]
        );
        assert_eq!(
            triangles_of(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![[0, 1, 2], [0, 2, 3]]
        );
        assert_eq!(
            triangles_of(Mode::Triangles, &[0, 1, 2, 3]),
            vec![[0, 1, 2]]
        );
    }
}
