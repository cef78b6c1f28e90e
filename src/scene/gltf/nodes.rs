//! A glTF scene's node graph: nodes visited from the scene's roots with their transforms
//! composed in f64, each mesh placed once per node that uses it, skins posed by their joints.

use super::*;

/// The triangles a primitive makes, from its accessors' counts (nothing is read): its
/// indices', else its positions', by mode; none for points, lines and a primitive without
/// positions.
fn primitive_triangles(p: &::gltf::Primitive) -> u64 {
    let count = match (p.indices(), p.get(&::gltf::Semantic::Positions)) {
        (Some(i), _) => i.count(),
        (None, Some(pos)) => pos.count(),
        (None, None) => return 0,
    } as u64;
    match p.mode() {
        Mode::Triangles => count / 3,
        Mode::TriangleStrip | Mode::TriangleFan => count.saturating_sub(2),
        _ => 0,
    }
}

/// Each vertex's transform under a skin: its joints' matrices blended by its weights
/// (normalised to sum to 1; a vertex with no weight keeps the node's `world`). A joint past
/// the skin's list is an error.
pub(super) fn skinning(
    at: &str,
    joints: &[DMat4],
    influences: &Influences,
    world: &DMat4,
) -> Result<Vec<Transform>> {
    influences
        .iter()
        .map(|inf| {
            let (mut m, mut sum) = (DMat4::ZERO, 0.0);
            for &(j, w) in inf {
                let Some(jm) = joints.get(j as usize) else {
                    bail!(
                        "{at}: a vertex names joint {j} of a skin with {} joints",
                        joints.len()
                    );
                };
                m += *jm * f64::from(w);
                sum += f64::from(w);
            }
            Ok(Transform::of(&if sum > 0.0 {
                m * (1.0 / sum)
            } else {
                *world
            }))
        })
        .collect()
}

impl Loader<'_> {
    /// Node `index` reached at `depth` below a root, `on_path` marking its ancestors: an
    /// error when it is its own ancestor (a cycle) or too deep.
    fn check_path(&self, index: usize, on_path: &[bool], depth: usize) -> Result<()> {
        if on_path[index] {
            bail!(
                "{}: nodes[{index}]: the node hierarchy has a cycle (nodes[{index}] is its own ancestor)",
                self.name
            );
        }
        if depth > MAX_NODE_DEPTH {
            bail!(
                "{}: nodes[{index}]: the node hierarchy is deeper than {MAX_NODE_DEPTH} levels",
                self.name
            );
        }
        Ok(())
    }

    /// Walks the node hierarchy from `roots` as [`Loader::visit`] will, counting placements
    /// and the triangles they place from the accessors' counts alone, and refuses a file that
    /// places too many before any of them is read: a small file whose nodes place a mesh many
    /// times over asks for memory it would take only while placing. Finds the meshes to hold
    /// once ([`Loader::share`]): those several nodes place, none with a skin, no primitive
    /// with morph targets.
    pub(super) fn plan(&mut self, roots: &[usize]) -> Result<()> {
        // Per mesh: its triangles, how many nodes place it, whether one of them skins it.
        let mut per_mesh: HashMap<usize, (u64, u64, bool)> = HashMap::new();
        let mut placements = 0usize;
        let mut on_path = vec![false; self.nodes.len()];
        // Depth-first, as `visit` goes: (node, depth, whether its children are done).
        let mut stack: Vec<(usize, usize, bool)> =
            roots.iter().rev().map(|&r| (r, 0, false)).collect();
        while let Some((index, depth, done)) = stack.pop() {
            if done {
                on_path[index] = false;
                continue;
            }
            let Some(node) = self.nodes.get(index) else {
                bail!("{}: nodes[{index}] does not exist", self.name);
            };
            self.check_path(index, &on_path, depth)?;
            placements += 1;
            if placements > MAX_NODE_VISITS {
                bail!(
                    "{}: the node hierarchy places more than {MAX_NODE_VISITS} nodes (nodes under several parents?)",
                    self.name
                );
            }
            if let Some(mesh) = node.mesh() {
                let e = per_mesh.entry(mesh.index()).or_insert_with(|| {
                    let n = mesh.primitives().map(|p| primitive_triangles(&p)).sum();
                    (n, 0, false)
                });
                e.1 += 1;
                e.2 |= node.skin().is_some();
            }
            on_path[index] = true;
            stack.push((index, depth, true));
            let children: Vec<usize> = node.children().map(|c| c.index()).collect();
            stack.extend(children.into_iter().rev().map(|c| (c, depth + 1, false)));
        }
        let morphed = |m: usize| {
            self.nodes
                .iter()
                .find_map(|n| n.mesh().filter(|x| x.index() == m))
                .is_some_and(|mesh| {
                    mesh.primitives()
                        .any(|p| p.morph_targets().next().is_some())
                })
        };
        let (mut held, mut placed, mut largest) = (0u64, 0u64, (0usize, 0u64));
        let mut meshes: Vec<(&usize, &(u64, u64, bool))> = per_mesh.iter().collect();
        meshes.sort_unstable();
        for (&m, &(n, uses, skinned)) in meshes {
            if uses >= 2 && !skinned && !morphed(m) {
                self.share.insert(m);
                held += n;
                placed += uses * n;
            } else {
                held += uses * n;
            }
            if uses * n > largest.1 {
                largest = (m, uses * n);
            }
        }
        if held > MAX_TRIANGLES as u64 {
            bail!(
                "{}: its nodes place more than {MAX_TRIANGLES} triangles ({placements} placements; meshes[{}] makes {}); such a scene is not loaded",
                self.name,
                largest.0,
                largest.1
            );
        }
        if placed > crate::bvh::MAX_PLACED {
            bail!(
                "{}: its nodes place {placed} triangles of meshes held once, more than the {} one scene can number",
                self.name,
                crate::bvh::MAX_PLACED
            );
        }
        Ok(())
    }

    pub(super) fn visit(
        &mut self,
        index: usize,
        parent: DMat4,
        on_path: &mut [bool],
        depth: usize,
    ) -> Result<()> {
        self.check_path(index, on_path, depth)?;
        self.visits += 1;
        if self.visits > MAX_NODE_VISITS {
            bail!(
                "{}: the node hierarchy places more than {MAX_NODE_VISITS} nodes (nodes under several parents?)",
                self.name
            );
        }
        let Some(node) = self.nodes.get(index).cloned() else {
            bail!("{}: nodes[{index}] does not exist", self.name);
        };
        let local = self.pose.local(index, &node);
        let world = parent * local;
        if !world.is_finite() {
            bail!("{}: nodes[{index}]: its transform is not finite", self.name);
        }
        if let Some(mesh) = node.mesh()
            && self.share.contains(&mesh.index())
        {
            // Held once: this node is one of its placements (one that scales it to nothing
            // shows nothing, and is left out).
            if world.determinant() != 0.0 {
                self.placed.push((mesh.index(), world));
            }
        } else if let Some(mesh) = node.mesh() {
            // Morph targets at the animated weights, else the node's, else the mesh's.
            let weights = self
                .pose
                .weights(index)
                .or(node.weights())
                .or(mesh.weights())
                .unwrap_or(&[])
                .to_vec();
            let weights = &weights[..];
            // A skinned mesh is placed by its joints; the node's own transform is ignored,
            // as the specification asks.
            let skin = match node.skin() {
                Some(skin) => Some(self.joint_matrices(&skin)?),
                None => None,
            };
            let before = self.buf.material_ids.len();
            for prim in mesh.primitives() {
                self.place(
                    mesh.index(),
                    prim,
                    weights,
                    &world,
                    skin.as_deref().map(Vec::as_slice),
                )?;
            }
            let name = node
                .name()
                .or(mesh.name())
                .map_or_else(|| format!("node {index}"), str::to_string);
            self.runs.push(name, self.buf.material_ids.len() - before);
        }
        if self.camera.is_none()
            && let Some(cam) = node.camera()
        {
            match cam.projection() {
                ::gltf::camera::Projection::Perspective(p) => {
                    let forward = world.transform_vector3(-DVec3::Z).normalize_or_zero();
                    let up = world.transform_vector3(DVec3::Y).normalize_or_zero();
                    if forward != DVec3::ZERO && up != DVec3::ZERO {
                        self.camera = Some(GltfCamera {
                            position: world.transform_point3(DVec3::ZERO),
                            forward,
                            up,
                            vfov_deg: p.yfov().to_degrees().clamp(1.0, 179.0),
                        });
                    }
                }
                ::gltf::camera::Projection::Orthographic(_) => self.warnings.push(format!(
                    "{}: cameras[{}]: orthographic cameras are not supported; skipped",
                    self.name,
                    cam.index()
                )),
            }
        }
        if let Some(light) = node.light() {
            use ::gltf::khr_lights_punctual::Kind;
            let (kind, cone) = match light.kind() {
                Kind::Point => (LightKind::Point, None),
                Kind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } => {
                    // The specification asks for 0 <= inner < outer <= pi / 2; a cone outside
                    // that is clamped into it, with a warning.
                    let or = |a: f32, default: f32| if a.is_finite() { a } else { default };
                    let outer = or(outer_cone_angle, std::f32::consts::FRAC_PI_4)
                        .clamp(1e-4, std::f32::consts::FRAC_PI_2);
                    let inner = or(inner_cone_angle, 0.0).clamp(0.0, outer * 0.9999);
                    if !(outer == outer_cone_angle && inner == inner_cone_angle) {
                        self.warnings.push(format!(
                            "{}: lights[{}]: spot cone angles {inner_cone_angle} and \
                             {outer_cone_angle} are outside 0 <= inner < outer <= pi/2; \
                             used {inner} and {outer}",
                            self.name,
                            light.index()
                        ));
                    }
                    (LightKind::Spot, Some((inner, outer)))
                }
                Kind::Directional => (LightKind::Directional, None),
            };
            let intensity = light.intensity();
            if intensity.is_finite() && intensity >= 0.0 {
                self.lights.push(GltfLight {
                    kind,
                    position: world.transform_point3(DVec3::ZERO),
                    direction: world.transform_vector3(-DVec3::Z).normalize_or(-DVec3::Z),
                    color: Vec3::from(light.color()),
                    intensity,
                    cone,
                });
            }
        }
        on_path[index] = true;
        for child in node.children() {
            self.visit(child.index(), world, on_path, depth + 1)?;
        }
        on_path[index] = false;
        Ok(())
    }

    /// Places one primitive with the node's world transform, its morph targets at `weights`,
    /// or by the joint matrices of the node's skin.
    pub(super) fn place(
        &mut self,
        mesh: usize,
        prim: ::gltf::Primitive,
        weights: &[f32],
        world: &DMat4,
        skin: Option<&[DMat4]>,
    ) -> Result<()> {
        let key = (
            mesh,
            prim.index(),
            weights.iter().map(|w| w.to_bits()).collect(),
            skin.is_some(),
        );
        let data = match self.primitives.get(&key) {
            Some(d) => d.clone(),
            None => {
                let skinned = skin.is_some();
                let d = self
                    .read_primitive(mesh, &prim, weights, skinned)?
                    .map(Arc::new);
                self.primitives.insert(key, d.clone());
                d
            }
        };
        let Some(p) = data else {
            return Ok(());
        };
        if self.buf.material_ids.len() + p.triangles.len() > MAX_TRIANGLES {
            bail!(
                "{}: meshes[{mesh}] placed again would make more than {MAX_TRIANGLES} triangles",
                self.name
            );
        }
        let at = format!("{}: meshes[{mesh}].primitives[{}]", self.name, prim.index());
        // Each vertex's transform: the node's, or the blend of its joints' for a skin.
        let skinned = match (skin, &p.influences) {
            (Some(joints), Some(influences)) => Some(skinning(&at, joints, influences, world)?),
            (Some(_), None) => {
                self.warnings.push(format!(
                    "{at}: its node has a skin but the primitive has no JOINTS_0; placed by the node's transform"
                ));
                None
            }
            _ => None,
        };
        let one = Transform::of(world);
        let xf = |i: usize| skinned.as_ref().map_or(&one, |s| &s[i]);
        for (ti, t) in p.triangles.iter().enumerate() {
            // A mirroring transform turns the winding around: corners are swapped back so
            // that the front face stays the front face.
            let flip = xf(t[0] as usize).flip;
            let order: [usize; 3] = if flip { [0, 2, 1] } else { [0, 1, 2] };
            let c = order.map(|k| t[k] as usize);
            self.buf
                .positions
                .extend(c.map(|i| xf(i).full.transform_point3(p.positions[i].as_dvec3())));
            let turn =
                |i: usize, n: Vec3| (xf(i).normal * n.as_dvec3()).normalize_or_zero().as_vec3();
            self.buf
                .normals
                .push(match (&p.normals, &p.corner_normals) {
                    (Some(n), _) => Some(c.map(|i| turn(i, n[i]))),
                    (None, Some(cn)) => Some(order.map(|k| turn(t[k] as usize, cn[ti][k]))),
                    (None, None) => None,
                });
            self.buf.uvs.push(match &p.uvs {
                Some(uv) => c.map(|i| uv[i]),
                None => [Vec2::ZERO; 3],
            });
            self.buf.uvs1.push(match &p.uvs1 {
                Some(uv) => c.map(|i| uv[i]),
                None => [Vec2::ZERO; 3],
            });
            // Tangents turn as positions do; a mirror turns the bitangent's handedness.
            self.buf.tangents.push(p.tangents.as_ref().map(|t| {
                c.map(|i| {
                    let v = (xf(i).linear * t[i].truncate().as_dvec3()).normalize_or_zero();
                    v.as_vec3().extend(if flip { -t[i].w } else { t[i].w })
                })
            }));
            self.buf.material_ids.push(p.material);
        }
        Ok(())
    }

    /// A skin's joint matrices: each joint node's world transform times its inverse bind
    /// matrix (the identity when the skin gives none).
    pub(super) fn joint_matrices(&mut self, skin: &::gltf::Skin) -> Result<Arc<Vec<DMat4>>> {
        if let Some(m) = self.skins.get(&skin.index()) {
            return Ok(m.clone());
        }
        let at = format!("{}: skins[{}]", self.name, skin.index());
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        let inverse_bind: Vec<DMat4> = match skin.inverse_bind_matrices() {
            Some(acc) => {
                let what = "inverseBindMatrices";
                self.check_accessor(&at, what, &acc, &[DataType::F32], Dimensions::Mat4)?;
                let buffers = self.buffers;
                let m: Vec<DMat4> = skin
                    .reader(|b| buffers.get(b.index()).and_then(|d| d.as_deref().ok()))
                    .read_inverse_bind_matrices()
                    .ok_or_else(|| anyhow!("{at}: {what} cannot be read"))?
                    .map(|m| DMat4::from_cols_array_2d(&m.map(|c| c.map(f64::from))))
                    .collect();
                if m.len() < joints.len() {
                    bail!("{at}: {} {what} for {} joints", m.len(), joints.len());
                }
                m
            }
            None => vec![DMat4::IDENTITY; joints.len()],
        };
        let mut out = Vec::with_capacity(joints.len());
        for (&j, ib) in joints.iter().zip(inverse_bind) {
            let m = self.world_of(j)? * ib;
            if !m.is_finite() {
                bail!("{at}: the matrix of joint nodes[{j}] is not finite");
            }
            out.push(m);
        }
        let out = Arc::new(out);
        self.skins.insert(skin.index(), out.clone());
        Ok(out)
    }

    /// A node's world transform, through its parents (the first that lists it).
    pub(super) fn world_of(&self, node: usize) -> Result<DMat4> {
        let mut m = DMat4::IDENTITY;
        let mut i = node;
        for _ in 0..=MAX_NODE_DEPTH {
            let Some(n) = self.nodes.get(i) else {
                bail!("{}: nodes[{i}] does not exist", self.name);
            };
            m = self.pose.local(i, n) * m;
            match self.parents[i] {
                Some(p) => i = p,
                None => return Ok(m),
            }
        }
        bail!(
            "{}: nodes[{node}]: its ancestors are deeper than {MAX_NODE_DEPTH} levels (or a cycle)",
            self.name
        )
    }
}
