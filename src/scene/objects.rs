//! The scene's objects: what its files name (an OBJ's objects, a glTF node's mesh, a PLY, a
//! scene file's mesh entry, each copy of a grid), each either a run of the scene's own
//! triangles ([`super::Scene::mesh`]) or one placement of a mesh held once
//! ([`super::Instances`]). The viewer makes each an entity; moving one that lies among the
//! scene's own triangles lifts it out of them into a mesh of its own, placed once
//! ([`super::Scene::lifted`]), so that what moves it afterwards is its placement.

use std::sync::Arc;

use glam::{Affine3A, Vec3};

use super::{Instances, PlaceError, Scene};
use crate::bvh::Instance;
use crate::geometry::Aabb;

/// One object of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    /// What the file calls it (an OBJ object's name, a glTF node's), or what the loader
    /// made of the file's name where it names none.
    pub name: String,
    /// Where its triangles are.
    pub place: Place,
}

/// Where an object's triangles are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    /// Triangles `first..first + count` of the scene's own ([`Scene::mesh`]).
    Own {
        /// Its first triangle.
        first: u32,
        /// How many.
        count: u32,
    },
    /// A placement of one of [`Scene::instances`]' meshes (an index into its placements).
    Placed(usize),
}

/// Named runs of a mesh's triangles, in order, as a loader appends them: what becomes the
/// scene's objects among its own triangles.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Runs(Vec<(String, u32)>);

impl Runs {
    /// Names the next `count` triangles `name` (joined to the run before when it has the same
    /// name: an OBJ object of several materials is one object).
    pub fn push(&mut self, name: impl Into<String>, count: usize) {
        let name = name.into();
        let count = u32::try_from(count).unwrap_or(u32::MAX);
        if count == 0 {
            return;
        }
        match self.0.last_mut() {
            Some((last, n)) if *last == name => *n = n.saturating_add(count),
            _ => self.0.push((name, count)),
        }
    }

    /// Appends another mesh's runs, each name under `prefix/` when one is given.
    pub fn extend(&mut self, other: Runs, prefix: Option<&str>) {
        for (name, count) in other.0 {
            let name = match prefix {
                Some(p) if p != name => format!("{p}/{name}"),
                _ => name,
            };
            self.push(name, count as usize);
        }
    }

    /// Triangles named.
    pub fn total(&self) -> u64 {
        self.0.iter().map(|r| r.1 as u64).sum()
    }

    /// Whether nothing is named.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// The objects of a scene of `own` triangles of its own, named by `runs` (the triangles past
/// them, if any, make one more object called `rest`), and of `placements` (named `mesh m #k`).
pub fn list(runs: &Runs, own: usize, placements: &[Instance], rest: &str) -> Vec<Object> {
    let mut objects = Vec::with_capacity(runs.0.len() + placements.len() + 1);
    let mut first = 0u32;
    let own = u32::try_from(own).unwrap_or(u32::MAX);
    for (name, count) in &runs.0 {
        let count = (*count).min(own - first);
        if count == 0 {
            break;
        }
        objects.push(Object {
            name: name.clone(),
            place: Place::Own { first, count },
        });
        first += count;
    }
    if first < own {
        objects.push(Object {
            name: rest.to_string(),
            place: Place::Own {
                first,
                count: own - first,
            },
        });
    }
    objects.extend(placements.iter().enumerate().map(|(k, p)| Object {
        name: format!("mesh {} #{k}", p.mesh),
        place: Place::Placed(k),
    }));
    objects
}

impl Scene {
    /// The object triangle `prim` belongs to (an index into [`Scene::objects`]).
    pub fn object_of(&self, prim: u32) -> Option<usize> {
        let own = self.mesh.triangles.len() as u32;
        let wanted = if prim < own {
            None
        } else if (prim as u64) < own as u64 + self.instances.triangle_count() {
            Some(self.instances.placement_of(prim - own))
        } else {
            return None;
        };
        self.objects.iter().position(|o| match (o.place, wanted) {
            (Place::Own { first, count }, None) => (first..first + count).contains(&prim),
            (Place::Placed(p), Some(w)) => p == w,
            _ => false,
        })
    }

    /// Object `i`'s frame and its box in it: for a placement, its transform and its mesh's
    /// box; for triangles of the scene's own, a frame at the centre of their box, unturned
    /// (what [`Scene::lifted`] places them by).
    pub fn object_frame(&self, i: usize) -> Option<(Affine3A, Aabb)> {
        match self.objects.get(i)?.place {
            Place::Placed(p) => {
                let placement = self.instances.placements().get(p)?;
                let mesh = self.instances.meshes.get(placement.mesh as usize)?;
                Some((placement.to_world, mesh.bounds()))
            }
            Place::Own { first, count } => {
                let range = first as usize..(first + count) as usize;
                let b = Aabb::of_finite_points(
                    self.mesh.triangles.get(range)?.iter().flatten().copied(),
                );
                if b.is_empty() {
                    return Some((Affine3A::IDENTITY, b));
                }
                let centre = (Vec3::from(b.min) + Vec3::from(b.max)) * 0.5;
                let local = Aabb::of_finite_points([
                    Vec3::from(b.min) - centre,
                    Vec3::from(b.max) - centre,
                ]);
                Some((Affine3A::from_translation(centre), local))
            }
        }
    }

    /// The same scene with object `i` placed by `to_world`: a placement moved, or triangles
    /// of the scene's own lifted out of them into a mesh of their own (in the frame
    /// [`Scene::object_frame`] gives them) placed once. Lifting numbers the triangles anew (the
    /// scene's own after it, then the placements with the new one last); every object keeps
    /// its index in [`Scene::objects`].
    ///
    /// A rectangle light that emissive triangles of the object lie in (the light they show:
    /// [`super::Light::holds_triangle`]) moves with the object, so the light is where its
    /// triangles are.
    pub fn lifted(&self, i: usize, to_world: Affine3A) -> Result<Scene, PlaceError> {
        let object = self.objects.get(i).ok_or(PlaceError::NoObject(i))?;
        let (frame, _) = self.object_frame(i).ok_or(PlaceError::NoObject(i))?;
        let carried = self.lights_of(i);
        let by = to_world * frame.inverse();
        let carry = |scene: &mut Scene| {
            for &l in &carried {
                scene.lights[l] = scene.lights[l].moved(by);
            }
        };
        let (first, count) = match object.place {
            Place::Placed(p) => {
                let mut scene = self.clone();
                scene.instances = self.instances.moved(&[(p, to_world)])?;
                carry(&mut scene);
                return Ok(scene);
            }
            Place::Own { first, count } => (first, count),
        };
        let centre = Vec3::from(frame.translation);
        let mut scene = self.clone();
        let range = first as usize..(first + count) as usize;
        let mut mesh = scene.mesh.split_off(range);
        mesh.triangles
            .iter_mut()
            .for_each(|t| *t = t.map(|v| v - centre));
        mesh.origin = self.mesh.origin + centre.as_dvec3();
        let index = self.instances.meshes.len() as u32;
        let mut meshes = self.instances.meshes.clone();
        meshes.push(Arc::new(mesh));
        let mut placements = self.instances.placements().to_vec();
        placements.push(Instance {
            mesh: index,
            to_world,
        });
        scene.instances = Instances::new(meshes, placements, scene.mesh.triangles.len() as u64)?;
        let placement = scene.instances.placements().len() - 1;
        for o in &mut scene.objects {
            if let Place::Own { first: f, .. } = &mut o.place
                && *f > first
            {
                *f -= count;
            }
        }
        scene.objects[i].place = Place::Placed(placement);
        carry(&mut scene);
        Ok(scene)
    }

    /// The rectangle lights that some emissive triangle of object `i` lies in.
    pub fn lights_of(&self, i: usize) -> Vec<usize> {
        let Some(object) = self.objects.get(i) else {
            return Vec::new();
        };
        let own = self.mesh.triangles.len() as u32;
        let prims = match object.place {
            Place::Own { first, count } => first..first + count,
            Place::Placed(p) => {
                let Some(placement) = self.instances.placements().get(p) else {
                    return Vec::new();
                };
                let first = own + self.instances.first_triangle(p);
                let n = self.instances.meshes[placement.mesh as usize]
                    .triangles
                    .len() as u32;
                first..first + n
            }
        };
        let glowing: Vec<[Vec3; 3]> = prims
            .filter(|&prim| {
                self.materials
                    .get(self.material_id(prim) as usize)
                    .is_some_and(|m| m.is_emissive())
            })
            .map(|prim| self.triangle(prim))
            .collect();
        (0..self.lights.len())
            .filter(|&l| glowing.iter().any(|t| self.lights[l].holds_triangle(t)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_join_a_name_repeated_and_skip_empty_ones() {
        let mut r = Runs::default();
        r.push("a", 2);
        r.push("a", 3);
        r.push("b", 0);
        r.push("c", 1);
        assert_eq!(r.0, vec![("a".into(), 5), ("c".into(), 1)]);
        assert_eq!(r.total(), 6);
        let mut outer = Runs::default();
        outer.extend(r, Some("box"));
        assert_eq!(outer.0[0].0, "box/a");
    }

    #[test]
    fn a_list_names_every_triangle_once() {
        let mut r = Runs::default();
        r.push("a", 2);
        r.push("b", 10);
        // Runs past the triangles there are are cut to them; triangles past the runs are one
        // more object.
        let placed = [Instance {
            mesh: 0,
            to_world: Affine3A::IDENTITY,
        }; 2];
        let objects = list(&r, 5, &placed, "file");
        let places: Vec<Place> = objects.iter().map(|o| o.place).collect();
        assert_eq!(
            places,
            vec![
                Place::Own { first: 0, count: 2 },
                Place::Own { first: 2, count: 3 },
                Place::Placed(0),
                Place::Placed(1)
            ]
        );
        let objects = list(&Runs::default(), 4, &[], "file");
        assert_eq!(objects.len(), 1);
        assert_eq!(objects[0].name, "file");
        assert_eq!(objects[0].place, Place::Own { first: 0, count: 4 });
    }
}
