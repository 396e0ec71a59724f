//! The body model type shared by SMPL files and the built-in MakeHuman body, its loaders, and posing
//! (shape blend shapes, pose blend shapes, forward kinematics, linear blend skinning).
//!
//! Conventions: metres; rest-pose frame with y up, x towards the body's left, z forward (SMPL's);
//! faces counter-clockwise seen from outside; weights row-major `(V, 24)` over the SMPL joints.
//! This module must never guess: a body file that does not match what a key must hold is an error
//! naming the key.

use std::io::{Read, Seek};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, SmplDeformError};
use crate::fk::forward_kinematics;
use crate::lbs::lbs_vertices_exact_rest;
use crate::math::{Affine, Mat3};
use crate::npz::{NpzReader, NpzWriter};
use crate::skeleton::{NUM_JOINTS, NUM_POSE_FEATURES, SMPL_PARENTS};

/// Largest vertex count accepted from a file (SMPL has 6890, SMPL-X 10475, the built-in body 13380).
pub const MAX_VERTICES: u64 = 200_000;
/// Largest face count accepted from a file.
pub const MAX_FACES: u64 = 400_000;
/// Largest number of shape coefficients accepted from a file (SMPL-X ships 400).
pub const MAX_BETAS: u64 = 1000;

/// A texture atlas: UV coordinates and per-face UV indices (the smplx `vt`/`ft` convention).
#[derive(Clone, Debug, PartialEq)]
pub struct UvMap {
    /// UV coordinates in [0, 1], v pointing up (OBJ convention).
    pub vt: Vec<[f32; 2]>,
    /// For each face, the indices into `vt` of its three corners (same corner order as `faces`).
    pub ft: Vec<[u32; 3]>,
}

/// A skinned body model on the SMPL 24-joint tree.
#[derive(Clone, Debug)]
pub struct BodyModel {
    /// Rest-pose vertices (metres), before shape blend shapes.
    pub v_template: Vec<[f32; 3]>,
    /// Triangles (vertex indices, counter-clockwise seen from outside).
    pub faces: Vec<[u32; 3]>,
    /// Optional texture coordinates.
    pub uv: Option<UvMap>,
    /// Rest joint positions (metres) for zero betas; recomputed from `j_regressor` when present.
    pub joints_rest: Vec<[f32; 3]>,
    /// Skinning weights, row-major `(V, 24)`, each row summing to 1.
    pub weights: Vec<f32>,
    /// Parent of each joint (`None` for the root); parents precede children.
    pub parents: Vec<Option<usize>>,
    /// Shape blend shapes, `(V, 3, num_betas)` row-major (metres per unit beta), if any.
    pub shapedirs: Option<Vec<f32>>,
    /// Number of shape coefficients in `shapedirs` (0 without shape blend shapes).
    pub num_betas: usize,
    /// Pose blend shapes, `(V, 3, 207)` row-major (metres per unit of the R − I feature), if any.
    pub posedirs: Option<Vec<f32>>,
    /// Dense joint regressor `(24, V)` row-major, if any.
    pub j_regressor: Option<Vec<f32>>,
}

/// Pose parameters in the SMPL layout, as in `P.json` of `cargo xtask body`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SmplParams {
    /// Axis-angle rotations (radians), 3 per joint, 72 values; joint 0 = global orientation.
    pub pose: Vec<f32>,
    /// Shape coefficients; fewer than the model's are zero-padded; ignored by models without shape
    /// blend shapes (the built-in body).
    #[serde(default)]
    pub betas: Vec<f32>,
    /// Global translation (metres), applied after rotation.
    #[serde(default)]
    pub transl: [f32; 3],
}

impl SmplParams {
    /// The zero pose (rest pose) with zero betas and translation.
    pub fn zero() -> Self {
        Self {
            pose: vec![0.0; 3 * NUM_JOINTS],
            betas: Vec::new(),
            transl: [0.0; 3],
        }
    }
}

/// A posed body.
#[derive(Clone, Debug)]
pub struct PosedBody {
    /// Posed vertices (metres).
    pub vertices: Vec<[f32; 3]>,
    /// Posed joint positions (metres).
    pub joints: Vec<[f32; 3]>,
    /// Rest joint positions used (after shape blend shapes).
    pub joints_rest: Vec<[f32; 3]>,
    /// Skinning transforms `posed_from_rest` per bone (row-major 3×4), translation included.
    pub posed_from_rest: Vec<Affine<f32>>,
    /// Local joint rotations (row-major 3×3).
    pub local_rotations: Vec<Mat3<f32>>,
}

/// Which body model a reference string names.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BodyRef {
    /// The built-in MakeHuman body (`builtin:makehuman`).
    BuiltinMakehuman,
    /// An SMPL `.npz` file.
    SmplFile(PathBuf),
}

impl BodyRef {
    /// Parses `builtin:makehuman` or a path.
    pub fn parse(s: &str) -> Result<Self> {
        if s == "builtin:makehuman" {
            Ok(Self::BuiltinMakehuman)
        } else if s.starts_with("builtin:") {
            Err(SmplDeformError::UnknownModel(s.into()))
        } else {
            Ok(Self::SmplFile(PathBuf::from(s)))
        }
    }

    /// Loads the referenced model.
    pub fn load(&self) -> Result<BodyModel> {
        match self {
            Self::BuiltinMakehuman => BodyModel::builtin_makehuman(),
            Self::SmplFile(p) => BodyModel::load_smpl_npz(p),
        }
    }
}

/// Path of the committed built-in body file: `<workspace>/data-fixtures/body/makehuman.npz`,
/// found at run time through this crate's `CARGO_MANIFEST_DIR` (so the workspace must be present).
pub fn builtin_makehuman_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-fixtures/body/makehuman.npz")
}

fn shape_is(expected: &[u64]) -> impl Fn(&[u64]) -> bool + '_ {
    move |s: &[u64]| s == expected
}

fn to_vec3(data: &[f64]) -> Vec<[f32; 3]> {
    data.chunks_exact(3)
        .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
        .collect()
}

fn faces_from(key: &str, data: &[i64], bound: usize) -> Result<Vec<[u32; 3]>> {
    let mut out = Vec::with_capacity(data.len() / 3);
    for c in data.chunks_exact(3) {
        let mut f = [0u32; 3];
        for k in 0..3 {
            if c[k] < 0 || c[k] as u64 >= bound as u64 {
                return Err(SmplDeformError::IndexOutOfRange {
                    key: key.into(),
                    index: c[k],
                    bound,
                });
            }
            f[k] = c[k] as u32;
        }
        out.push(f);
    }
    Ok(out)
}

/// Validates a `kintree_table` of shape (2, 24) and returns the parents.
fn parents_from_kintree(data: &[i64]) -> Result<Vec<Option<usize>>> {
    let key = "kintree_table";
    let not_tree = |reason: String| SmplDeformError::NotATree {
        key: key.into(),
        reason,
    };
    let (par, ids) = data.split_at(NUM_JOINTS);
    for (j, &id) in ids.iter().enumerate() {
        if id != j as i64 {
            return Err(not_tree(format!(
                "row 1 must list joints 0..24 in order, found {id} at column {j}"
            )));
        }
    }
    let mut parents = Vec::with_capacity(NUM_JOINTS);
    for (j, &p) in par.iter().enumerate() {
        if j == 0 {
            if p != -1 {
                return Err(not_tree(format!(
                    "joint 0 must be the root (parent -1 or 4294967295), found {p}"
                )));
            }
            parents.push(None);
        } else if p < 0 {
            return Err(not_tree(format!("joint {j} is a second root")));
        } else if p as usize >= j {
            return Err(not_tree(format!(
                "joint {j} has parent {p}: parents must precede children (no cycles)"
            )));
        } else {
            parents.push(Some(p as usize));
        }
    }
    Ok(parents)
}

fn check_weights(key: &str, weights: &[f32]) -> Result<()> {
    for (v, row) in weights.chunks_exact(NUM_JOINTS).enumerate() {
        let s: f32 = row.iter().sum();
        if row.iter().any(|&w| w < -1e-6) || (s - 1.0).abs() > 1e-3 {
            return Err(SmplDeformError::BadArray {
                key: key.into(),
                message: format!("row {v} is not a convex combination (sum {s})"),
            });
        }
    }
    Ok(())
}

impl BodyModel {
    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.v_template.len()
    }

    /// Loads an SMPL model from `.npz` (keys `v_template (V,3)`, `shapedirs (V,3,B)`,
    /// `posedirs (V,3,207)` or `(207, 3V)`, `J_regressor (24,V)` dense, `weights (V,24)`,
    /// `kintree_table (2,24)`, `f (F,3)`; f32 or f64; any B ≤ [`MAX_BETAS`]).
    pub fn load_smpl_npz(path: &Path) -> Result<Self> {
        let mut r = NpzReader::open(path)?;
        Self::read_npz(&mut r, true)
    }

    /// Like [`Self::load_smpl_npz`] from any seekable reader.
    pub fn load_smpl_npz_from<R: Read + Seek>(reader: R) -> Result<Self> {
        let mut r = NpzReader::new(reader)?;
        Self::read_npz(&mut r, true)
    }

    /// Loads the built-in MakeHuman body from [`builtin_makehuman_path`].
    ///
    /// It has no shape or pose blend shapes: betas are accepted and ignored.
    pub fn builtin_makehuman() -> Result<Self> {
        Self::load_body_npz(&builtin_makehuman_path())
    }

    /// Loads a body `.npz` in the built-in layout (`v_template`, `f`, `weights`, `kintree_table`,
    /// `J (24,3)`, optional `vt (T,2)`/`ft (F,3)`; blend shapes and regressor optional).
    pub fn load_body_npz(path: &Path) -> Result<Self> {
        let mut r = NpzReader::open(path)?;
        Self::read_npz(&mut r, false)
    }

    fn read_npz<R: Read + Seek>(r: &mut NpzReader<R>, smpl: bool) -> Result<Self> {
        let required: &[&str] = if smpl {
            &[
                "v_template",
                "shapedirs",
                "posedirs",
                "J_regressor",
                "weights",
                "kintree_table",
                "f",
            ]
        } else {
            &["v_template", "weights", "kintree_table", "f", "J"]
        };
        for key in required {
            if !r.has(key) {
                return Err(SmplDeformError::MissingKey { key: (*key).into() });
            }
        }
        let (shape, vt) = r.read_float(
            "v_template",
            |s| s.len() == 2 && s[1] == 3 && s[0] > 0 && s[0] <= MAX_VERTICES,
            "(V, 3) with 0 < V <= 200000",
        )?;
        let nv = shape[0];
        let nvu = nv as usize;
        let v_template = to_vec3(&vt);
        let (_, f) = r.read_int(
            "f",
            |s| s.len() == 2 && s[1] == 3 && s[0] > 0 && s[0] <= MAX_FACES,
            "(F, 3)",
        )?;
        let faces = faces_from("f", &f, nvu)?;
        let (_, w) = r.read_float(
            "weights",
            shape_is(&[nv, NUM_JOINTS as u64]),
            &format!("({nv}, 24)"),
        )?;
        let weights: Vec<f32> = w.iter().map(|&x| x as f32).collect();
        check_weights("weights", &weights)?;
        let (_, kt) = r.read_int(
            "kintree_table",
            shape_is(&[2, NUM_JOINTS as u64]),
            "(2, 24)",
        )?;
        let parents = parents_from_kintree(&kt)?;

        let shapedirs = if r.has("shapedirs") {
            let (s, d) = r.read_float(
                "shapedirs",
                |s| s.len() == 3 && s[0] == nv && s[1] == 3 && s[2] <= MAX_BETAS,
                &format!("({nv}, 3, B) with B <= 1000"),
            )?;
            Some((
                s[2] as usize,
                d.iter().map(|&x| x as f32).collect::<Vec<_>>(),
            ))
        } else {
            None
        };
        let posedirs = if r.has("posedirs") {
            let p = NUM_POSE_FEATURES as u64;
            let (s, d) = r.read_float(
                "posedirs",
                |s| s == [nv, 3, p] || s == [p, 3 * nv],
                &format!("({nv}, 3, 207) or (207, {})", 3 * nv),
            )?;
            let data: Vec<f32> = if s.len() == 2 {
                // Flattened smplx form: [p][3v + c] -> [v][c][p].
                let np = NUM_POSE_FEATURES;
                let mut out = vec![0.0f32; nvu * 3 * np];
                for pi in 0..np {
                    for vc in 0..3 * nvu {
                        out[vc * np + pi] = d[pi * 3 * nvu + vc] as f32;
                    }
                }
                out
            } else {
                d.iter().map(|&x| x as f32).collect()
            };
            Some(data)
        } else {
            None
        };
        let j_regressor = if r.has("J_regressor") {
            let (_, d) = r.read_float(
                "J_regressor",
                shape_is(&[NUM_JOINTS as u64, nv]),
                &format!("(24, {nv})"),
            )?;
            Some(d.iter().map(|&x| x as f32).collect::<Vec<_>>())
        } else {
            None
        };
        let joints_rest = if let Some(jr) = &j_regressor {
            regress_joints(jr, &v_template)
        } else {
            let (_, j) = r.read_float("J", shape_is(&[NUM_JOINTS as u64, 3]), "(24, 3)")?;
            to_vec3(&j)
        };
        let uv = if r.has("vt") && r.has("ft") {
            let (s, t) = r.read_float(
                "vt",
                |s| s.len() == 2 && s[1] == 2 && s[0] > 0 && s[0] <= 4 * MAX_VERTICES,
                "(T, 2)",
            )?;
            let (_, ft) = r.read_int(
                "ft",
                shape_is(&[faces.len() as u64, 3]),
                &format!("({}, 3)", faces.len()),
            )?;
            Some(UvMap {
                vt: t
                    .chunks_exact(2)
                    .map(|c| [c[0] as f32, c[1] as f32])
                    .collect(),
                ft: faces_from("ft", &ft, s[0] as usize)?,
            })
        } else {
            None
        };
        let (num_betas, shapedirs) = match shapedirs {
            Some((b, d)) => (b, Some(d)),
            None => (0, None),
        };
        Ok(Self {
            v_template,
            faces,
            uv,
            joints_rest,
            weights,
            parents,
            shapedirs,
            num_betas,
            posedirs,
            j_regressor,
        })
    }

    /// Writes the model in the built-in `.npz` layout (f32 arrays, u32 indices, i64 kintree),
    /// deterministic bytes. Blend shapes and regressor are written when present.
    pub fn save_body_npz(&self, path: &Path) -> Result<()> {
        let io = |source| SmplDeformError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::create(path).map_err(io)?;
        let mut w = NpzWriter::new(std::io::BufWriter::new(file), true);
        let nv = self.num_vertices() as u64;
        let flat3: Vec<f32> = self.v_template.iter().flatten().copied().collect();
        w.add_f32("v_template", &[nv, 3], &flat3).map_err(io)?;
        let f: Vec<u32> = self.faces.iter().flatten().copied().collect();
        w.add_u32("f", &[self.faces.len() as u64, 3], &f)
            .map_err(io)?;
        w.add_f32("weights", &[nv, NUM_JOINTS as u64], &self.weights)
            .map_err(io)?;
        let mut kt = vec![0i64; 2 * NUM_JOINTS];
        for j in 0..NUM_JOINTS {
            kt[j] = self.parents[j].map_or(-1, |p| p as i64);
            kt[NUM_JOINTS + j] = j as i64;
        }
        w.add_i64("kintree_table", &[2, NUM_JOINTS as u64], &kt)
            .map_err(io)?;
        let j: Vec<f32> = self.joints_rest.iter().flatten().copied().collect();
        w.add_f32("J", &[NUM_JOINTS as u64, 3], &j).map_err(io)?;
        if let Some(uv) = &self.uv {
            let vt: Vec<f32> = uv.vt.iter().flatten().copied().collect();
            w.add_f32("vt", &[uv.vt.len() as u64, 2], &vt).map_err(io)?;
            let ft: Vec<u32> = uv.ft.iter().flatten().copied().collect();
            w.add_u32("ft", &[uv.ft.len() as u64, 3], &ft).map_err(io)?;
        }
        if let Some(sd) = &self.shapedirs {
            w.add_f32("shapedirs", &[nv, 3, self.num_betas as u64], sd)
                .map_err(io)?;
        }
        if let Some(pd) = &self.posedirs {
            w.add_f32("posedirs", &[nv, 3, NUM_POSE_FEATURES as u64], pd)
                .map_err(io)?;
        }
        if let Some(jr) = &self.j_regressor {
            w.add_f32("J_regressor", &[NUM_JOINTS as u64, nv], jr)
                .map_err(io)?;
        }
        w.finish().map_err(io)?;
        Ok(())
    }

    /// True when the parents are exactly SMPL's.
    pub fn has_smpl_tree(&self) -> bool {
        self.parents.as_slice() == SMPL_PARENTS.as_slice()
    }

    /// Rest vertices after shape blend shapes: `v_template + shapedirs · β` (accumulated in f32 in
    /// coefficient order). Betas beyond the model's are an error; missing ones are zero; models
    /// without shape blend shapes ignore betas.
    pub fn shaped_vertices(&self, betas: &[f32]) -> Result<Vec<[f32; 3]>> {
        check_finite("betas", betas)?;
        let Some(sd) = &self.shapedirs else {
            return Ok(self.v_template.clone());
        };
        if betas.len() > self.num_betas {
            return Err(SmplDeformError::InvalidParams {
                field: "betas".into(),
                reason: format!(
                    "{} values but the model has {} shape coefficients",
                    betas.len(),
                    self.num_betas
                ),
            });
        }
        let nb = self.num_betas;
        Ok(self
            .v_template
            .iter()
            .enumerate()
            .map(|(v, x)| {
                let mut out = *x;
                for c in 0..3 {
                    let row = &sd[(3 * v + c) * nb..(3 * v + c) * nb + betas.len()];
                    for (d, b) in row.iter().zip(betas) {
                        out[c] += d * b;
                    }
                }
                out
            })
            .collect())
    }

    /// Rest joints for the given shaped vertices (regressor when present, stored joints otherwise).
    pub fn rest_joints(&self, shaped: &[[f32; 3]]) -> Vec<[f32; 3]> {
        match &self.j_regressor {
            Some(jr) => regress_joints(jr, shaped),
            None => self.joints_rest.clone(),
        }
    }

    /// Poses the body: shape blend shapes, joints, forward kinematics (f64), pose blend shapes
    /// (feature `R_j − I` of joints 1..23, row-major), then linear blend skinning in displacement
    /// form (see [`lbs_vertices_exact_rest`]), so the zero pose reproduces the shaped rest mesh
    /// exactly.
    pub fn pose(&self, params: &SmplParams) -> Result<PosedBody> {
        if params.pose.len() != 3 * NUM_JOINTS {
            return Err(SmplDeformError::InvalidParams {
                field: "pose".into(),
                reason: format!("{} values, expected 72", params.pose.len()),
            });
        }
        check_finite("pose", &params.pose)?;
        check_finite("transl", &params.transl)?;
        let shaped = self.shaped_vertices(&params.betas)?;
        let joints_rest = self.rest_joints(&shaped);
        let pose64: Vec<f64> = params.pose.iter().map(|&x| f64::from(x)).collect();
        let j64: Vec<[f64; 3]> = joints_rest
            .iter()
            .map(|j| [f64::from(j[0]), f64::from(j[1]), f64::from(j[2])])
            .collect();
        let t = params.transl;
        let fk = forward_kinematics(
            &pose64,
            [f64::from(t[0]), f64::from(t[1]), f64::from(t[2])],
            &j64,
            &self.parents,
        );
        let posed_from_rest: Vec<Affine<f32>> = fk
            .posed_from_rest
            .iter()
            .map(|a| a.map(|x| x as f32))
            .collect();
        let local_rotations: Vec<Mat3<f32>> = fk
            .local_rotations
            .iter()
            .map(|a| a.map(|x| x as f32))
            .collect();
        let mut rest = shaped;
        if let Some(pd) = &self.posedirs {
            let feat = pose_feature(&local_rotations);
            if feat.iter().any(|&x| x != 0.0) {
                let np = NUM_POSE_FEATURES;
                for (v, x) in rest.iter_mut().enumerate() {
                    for c in 0..3 {
                        let row = &pd[(3 * v + c) * np..(3 * v + c + 1) * np];
                        let mut acc = 0.0f32;
                        for (d, f) in row.iter().zip(&feat) {
                            acc += d * f;
                        }
                        x[c] += acc;
                    }
                }
            }
        }
        let vertices = lbs_vertices_exact_rest(&self.weights, &posed_from_rest, &rest);
        Ok(PosedBody {
            vertices,
            joints: fk
                .joints_posed
                .iter()
                .map(|j| j.map(|x| x as f32))
                .collect(),
            joints_rest,
            posed_from_rest,
            local_rotations,
        })
    }

    /// Gradient of [`BodyModel::pose`]'s vertices w.r.t. the pose (72 values, through the skinning
    /// transforms *and* the pose blend shapes) and the translation, given `∂L/∂vertices`; evaluated
    /// in f64 by [`crate::pose_blend::pose_vertices_backward`] (betas are constants). Returns
    /// `(∂L/∂pose, ∂L/∂transl)`.
    pub fn pose_backward(
        &self,
        params: &SmplParams,
        d_vertices: &[[f32; 3]],
    ) -> Result<(Vec<f32>, [f32; 3])> {
        if params.pose.len() != 3 * NUM_JOINTS {
            return Err(SmplDeformError::InvalidParams {
                field: "pose".into(),
                reason: format!("{} values, expected 72", params.pose.len()),
            });
        }
        if d_vertices.len() != self.num_vertices() {
            return Err(SmplDeformError::InvalidParams {
                field: "d_vertices".into(),
                reason: format!(
                    "{} rows, expected one per vertex ({})",
                    d_vertices.len(),
                    self.num_vertices()
                ),
            });
        }
        check_finite("pose", &params.pose)?;
        check_finite("transl", &params.transl)?;
        let shaped = self.shaped_vertices(&params.betas)?;
        let joints = self.rest_joints(&shaped);
        let to64 =
            |v: &[[f32; 3]]| -> Vec<[f64; 3]> { v.iter().map(|x| x.map(f64::from)).collect() };
        let (shaped64, joints64, d64) = (to64(&shaped), to64(&joints), to64(d_vertices));
        let pose64: Vec<f64> = params.pose.iter().map(|&x| f64::from(x)).collect();
        let body = crate::pose_blend::PosingBody {
            shaped: &shaped64,
            joints_rest: &joints64,
            parents: &self.parents,
            weights: &self.weights,
            posedirs: self.posedirs.as_deref(),
        };
        let (_, cache) =
            crate::pose_blend::pose_vertices(&body, &pose64, params.transl.map(f64::from));
        let g = crate::pose_blend::pose_vertices_backward(&body, &pose64, &cache, &d64);
        Ok((
            g.pose.iter().map(|&x| x as f32).collect(),
            g.transl.map(|x| x as f32),
        ))
    }
}

/// The 207-value pose-blend-shape feature: `R_j − I` for joints 1..23, each row-major.
pub fn pose_feature(local_rotations: &[Mat3<f32>]) -> Vec<f32> {
    let mut out = Vec::with_capacity(NUM_POSE_FEATURES);
    for r in local_rotations.iter().skip(1) {
        for (k, &x) in r.iter().enumerate() {
            out.push(if k % 4 == 0 { x - 1.0 } else { x });
        }
    }
    out
}

fn regress_joints(jr: &[f32], verts: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let nv = verts.len();
    (0..NUM_JOINTS)
        .map(|j| {
            let mut acc = [0.0f64; 3];
            for (w, v) in jr[j * nv..(j + 1) * nv].iter().zip(verts) {
                if *w != 0.0 {
                    for c in 0..3 {
                        acc[c] += f64::from(*w) * f64::from(v[c]);
                    }
                }
            }
            acc.map(|x| x as f32)
        })
        .collect()
}

fn check_finite(field: &str, v: &[f32]) -> Result<()> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(SmplDeformError::InvalidParams {
            field: field.into(),
            reason: format!("non-finite value at index {i}"),
        });
    }
    Ok(())
}
