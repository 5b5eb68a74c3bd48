//! Scene traversal (glTF 2.0 specification, section 3.5 "Scenes" and 3.5.2 "Transformations"):
//! which nodes are drawn, and each mesh instance's node-to-world transform composed in f64.

use std::path::Path;

use ::gltf::json;

use crate::error::{ImportError, Position};

/// A column-major 4x4 matrix, as glTF stores `node.matrix`.
pub(super) type Mat4 = [f64; 16];

pub(super) const IDENTITY: Mat4 = [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.];

/// One drawn mesh: the node that draws it (None when a file without nodes has its meshes drawn
/// once each), the mesh, and the node's world transform.
#[derive(Clone, Debug)]
pub(super) struct Instance {
    pub node: Option<usize>,
    pub mesh: usize,
    pub matrix: Mat4,
}

/// `a * b`.
pub(super) fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [0.0; 16];
    for c in 0..4 {
        for r in 0..4 {
            m[c * 4 + r] = (0..4).map(|k| a[k * 4 + r] * b[c * 4 + k]).sum();
        }
    }
    m
}

/// Applies `m` to point `p`.
#[inline]
pub(super) fn transform_point(m: &Mat4, p: [f32; 3]) -> [f64; 3] {
    let [x, y, z] = p.map(f64::from);
    [
        m[0] * x + m[4] * y + m[8] * z + m[12],
        m[1] * x + m[5] * y + m[9] * z + m[13],
        m[2] * x + m[6] * y + m[10] * z + m[14],
    ]
}

/// Determinant of the upper-left 3x3 block.
pub(super) fn det3(m: &Mat4) -> f64 {
    m[0] * (m[5] * m[10] - m[9] * m[6]) - m[4] * (m[1] * m[10] - m[9] * m[2])
        + m[8] * (m[1] * m[6] - m[5] * m[2])
}

/// The normal matrix: the inverse transpose of the upper-left 3x3 block, row-major; `None` when
/// the block is singular (every triangle is then degenerate anyway).
pub(super) fn normal_matrix(m: &Mat4) -> Option<[[f64; 3]; 3]> {
    let det = det3(m);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    // a(r, c) is the element at row r, column c. The inverse transpose is cofactor / det.
    let a = |r: usize, c: usize| m[c * 4 + r];
    let cof = |r: usize, c: usize| {
        let (r0, r1) = ((r + 1) % 3, (r + 2) % 3);
        let (c0, c1) = ((c + 1) % 3, (c + 2) % 3);
        a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0)
    };
    Some(std::array::from_fn(|r| std::array::from_fn(|c| cof(r, c) / det)))
}

/// Applies the normal matrix and normalizes; a zero normal stays zero.
#[inline]
pub(super) fn transform_normal(n: &[[f64; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    let [x, y, z] = v.map(f64::from);
    let t = [0, 1, 2].map(|r| n[r][0] * x + n[r][1] * y + n[r][2] * z);
    let len = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    if len > 0.0 {
        t.map(|c| (c / len) as f32)
    } else {
        [0.0; 3]
    }
}

/// A node's local transform: its `matrix`, or translation * rotation * scale.
pub(super) fn local_matrix(node: &json::Node, index: usize, path: &Path) -> Result<Mat4, ImportError> {
    let bad =
        |what: &str| ImportError::parse(path, Position::File, format!("nodes[{index}].{what} is not finite"));
    if let Some(m) = node.matrix {
        if m.iter().any(|v| !v.is_finite()) {
            return Err(bad("matrix"));
        }
        return Ok(m.map(f64::from));
    }
    let t = node.translation.unwrap_or([0.0; 3]).map(f64::from);
    let s = node.scale.unwrap_or([1.0; 3]).map(f64::from);
    let q = node.rotation.as_ref().map_or([0.0, 0.0, 0.0, 1.0], |q| q.0).map(f64::from);
    if t.iter().any(|v| !v.is_finite()) {
        return Err(bad("translation"));
    }
    if s.iter().any(|v| !v.is_finite()) {
        return Err(bad("scale"));
    }
    let len = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if !len.is_finite() || len == 0.0 {
        return Err(ImportError::parse(
            path,
            Position::File,
            format!("nodes[{index}].rotation {q:?} is not a unit quaternion"),
        ));
    }
    let [x, y, z, w] = q.map(|c| c / len);
    let r = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ];
    let mut m = IDENTITY;
    for c in 0..3 {
        for row in 0..3 {
            m[c * 4 + row] = r[row][c] * s[c];
        }
    }
    m[12..15].copy_from_slice(&t);
    Ok(m)
}

/// Every mesh instance of the scene to draw, in depth-first node order: the default scene, else
/// scene 0, else (no scenes) every node without a parent, else (no nodes) every mesh once.
///
/// The node hierarchy must be a forest (section 3.5.1): a node reached twice, through a cycle or
/// through two parents, is an error; so a hostile file can neither loop nor multiply instances
/// exponentially. The walk uses an explicit stack, so depth is not limited by the call stack.
pub(super) fn instances(root: &json::Root, path: &Path) -> Result<Vec<Instance>, ImportError> {
    let err = |m: String| ImportError::parse(path, Position::File, m);
    let nodes = &root.nodes;
    let mut default_scene = root.scene;
    if let Some(s) = default_scene.filter(|_| root.scenes.is_empty()) {
        // Unambiguous enough to draw: without scenes, every parentless node is the scene.
        tracing::warn!(
            "{}: scene {} does not exist (no scenes); drawing every root node",
            path.display(),
            s.value()
        );
        default_scene = None;
    }
    let roots: Vec<(usize, String)> = match (default_scene, root.scenes.is_empty()) {
        (Some(s), _) => {
            let scene = root.scenes.get(s.value()).ok_or_else(|| {
                err(format!("scene {} does not exist ({} scenes)", s.value(), root.scenes.len()))
            })?;
            let i = s.value();
            scene
                .nodes
                .iter()
                .enumerate()
                .map(|(k, n)| (n.value(), format!("scenes[{i}].nodes[{k}]")))
                .collect()
        }
        (None, false) => root.scenes[0]
            .nodes
            .iter()
            .enumerate()
            .map(|(k, n)| (n.value(), format!("scenes[0].nodes[{k}]")))
            .collect(),
        (None, true) if nodes.is_empty() => {
            return Ok((0..root.meshes.len())
                .map(|mesh| Instance { node: None, mesh, matrix: IDENTITY })
                .collect());
        }
        (None, true) => {
            let mut has_parent = vec![false; nodes.len()];
            for (i, n) in nodes.iter().enumerate() {
                for (k, c) in n.children.iter().flatten().enumerate() {
                    let slot = has_parent.get_mut(c.value()).ok_or_else(|| {
                        err(format!("nodes[{i}].children[{k}]: nodes[{}] does not exist", c.value()))
                    })?;
                    *slot = true;
                }
            }
            (0..nodes.len()).filter(|&i| !has_parent[i]).map(|i| (i, String::new())).collect()
        }
    };
    let mut visited = vec![false; nodes.len()];
    let mut out = Vec::new();
    // (node, parent's world matrix, how it was reached)
    let mut stack: Vec<(usize, Mat4, String)> = Vec::new();
    for (r, how) in roots.into_iter() {
        stack.push((r, IDENTITY, how));
        while let Some((i, parent, how)) = stack.pop() {
            let node = nodes
                .get(i)
                .ok_or_else(|| err(format!("{how}: nodes[{i}] does not exist ({} nodes)", nodes.len())))?;
            if std::mem::replace(&mut visited[i], true) {
                return Err(err(format!(
                    "{how}: nodes[{i}] is reached twice; the node hierarchy must be a tree without cycles"
                )));
            }
            let world = mul(&parent, &local_matrix(node, i, path)?);
            if let Some(m) = node.mesh {
                if m.value() >= root.meshes.len() {
                    return Err(err(format!("nodes[{i}].mesh: meshes[{}] does not exist", m.value())));
                }
                out.push(Instance { node: Some(i), mesh: m.value(), matrix: world });
            }
            for (k, c) in node.children.as_deref().unwrap_or(&[]).iter().enumerate().rev() {
                stack.push((c.value(), world, format!("nodes[{i}].children[{k}]")));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trs_composes_translation_rotation_scale() {
        let mut n: json::Node = serde_json::from_str(
            r#"{"translation":[1,2,3],"rotation":[0,0,0.7071067811865476,0.7071067811865476],"scale":[2,2,2]}"#,
        )
        .unwrap();
        let m = local_matrix(&n, 0, Path::new("x")).unwrap();
        let p = transform_point(&m, [1.0, 0.0, 0.0]);
        // Scale to (2,0,0), rotate 90 degrees about z to (0,2,0), translate.
        assert!(
            (p[0] - 1.0).abs() < 1e-6 && (p[1] - 4.0).abs() < 1e-6 && (p[2] - 3.0).abs() < 1e-12,
            "{p:?}"
        );
        n.rotation = None;
        n.translation = Some([f32::NAN, 0.0, 0.0]);
        assert!(local_matrix(&n, 0, Path::new("x")).is_err());
    }

    #[test]
    fn normal_matrix_is_inverse_transpose() {
        // Non-uniform scale (2, 1, 1): a normal (1, 1, 0) becomes (0.5, 1, 0) normalized.
        let mut m = IDENTITY;
        m[0] = 2.0;
        let n = transform_normal(&normal_matrix(&m).unwrap(), [1.0, 1.0, 0.0]);
        let l = (0.25f32 + 1.0).sqrt();
        assert!((n[0] - 0.5 / l).abs() < 1e-6 && (n[1] - 1.0 / l).abs() < 1e-6 && n[2] == 0.0, "{n:?}");
        m[0] = -2.0;
        assert!(det3(&m) < 0.0);
        let n = transform_normal(&normal_matrix(&m).unwrap(), [1.0, 0.0, 0.0]);
        assert_eq!(n, [-1.0, 0.0, 0.0]);
        m[0] = 0.0;
        assert!(normal_matrix(&m).is_none());
    }
}
