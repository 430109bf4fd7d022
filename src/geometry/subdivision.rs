//! Subdivision surfaces, one concept in one file: Catmull-Clark (any polygons), Loop
//! (triangles) and bilinear refinement of a control cage, with semi-sharp creases and
//! corners (the Pixar rules of DeRose, Kass and Truong 1998, as OpenSubdiv applies them:
//! sharpness s < 1 blends the smooth and sharp rules by s, each level lowers sharpness by
//! one, 10 and above is infinitely sharp), USD's boundary interpolation (`edgeAndCorner`:
//! boundary edges sharp and boundary vertices of one face corners; `edgeOnly`: boundary
//! edges sharp only), and face-varying data (texture coordinates, colours) refined
//! bilinearly within each face, as USD's faceVaryingLinearInterpolation `all` does.
//!
//! After the last level every vertex is moved to its limit position (the eigen-analysis
//! masks of Catmull-Clark, Loop and the cubic B-spline along creases), so the triangles lie
//! on the limit surface; normals are the area-weighted normals of the refined faces, kept
//! apart across sharp edges (a crease stays a crease in the shading).
//!
//! The level is chosen by [`level_for`]: the smallest that brings the cage's mean edge to a
//! target length on screen, capped by [`MAX_LEVEL`] and the memory limit.

use crate::scene::{BoundaryInterpolation, Mesh, SubdivisionScheme, SubdivisionSurface};
use glam::{DVec3, Vec2, Vec4};
use rayon::prelude::*;

/// Deepest uniform refinement: 4⁶ = 4096 faces a quad.
pub const MAX_LEVEL: u32 = 6;

/// Sharpness at or above which an edge or vertex is infinitely sharp (USD and RenderMan).
const INFINITELY_SHARP: f32 = 10.0;

/// A cage during refinement: polygons (`counts`, `indices`), per-corner face-varying values
/// (`fvar`, `width` floats a corner), creases and corners, and which faces are rendered.
struct Cage {
    points: Vec<DVec3>,
    counts: Vec<u32>,
    starts: Vec<u32>,
    indices: Vec<u32>,
    width: usize,
    fvar: Vec<f32>,
    /// Sharpness of each edge (same order as `Edges::ends`), boundary edges infinite.
    edge_sharpness: Vec<f32>,
    vertex_sharpness: Vec<f32>,
    keep: Vec<bool>,
}

/// The edges of a cage: endpoints, and the corners (face corners starting each edge in
/// its face's winding) that use them.
struct Edges {
    ends: Vec<[u32; 2]>,
    /// Edge of each corner c: the edge from corner c to the next corner of its face.
    of_corner: Vec<u32>,
    /// Faces using each edge: CSR over `face_list`.
    face_start: Vec<u32>,
    face_list: Vec<u32>,
}

fn next_corner(cage: &Cage, face: usize, corner: usize) -> usize {
    let start = cage.starts[face] as usize;
    let n = cage.counts[face] as usize;
    start + (corner - start + 1) % n
}

fn build_edges(cage: &Cage) -> Edges {
    let corners = cage.indices.len();
    let mut keyed: Vec<(u64, u32)> = Vec::with_capacity(corners);
    for f in 0..cage.counts.len() {
        let start = cage.starts[f] as usize;
        for c in start..start + cage.counts[f] as usize {
            let a = cage.indices[c];
            let b = cage.indices[next_corner(cage, f, c)];
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            keyed.push(((lo as u64) << 32 | hi as u64, c as u32));
        }
    }
    keyed.par_sort_unstable();
    let mut ends = Vec::new();
    let mut of_corner = vec![0u32; corners];
    let mut face_start = vec![0u32];
    let mut face_list = Vec::with_capacity(corners);
    let mut face_of_corner = vec![0u32; corners];
    for f in 0..cage.counts.len() {
        let start = cage.starts[f] as usize;
        face_of_corner[start..start + cage.counts[f] as usize].fill(f as u32);
    }
    let mut i = 0;
    while i < keyed.len() {
        let key = keyed[i].0;
        let edge = ends.len() as u32;
        ends.push([(key >> 32) as u32, key as u32]);
        while i < keyed.len() && keyed[i].0 == key {
            let c = keyed[i].1 as usize;
            of_corner[c] = edge;
            face_list.push(face_of_corner[c]);
            i += 1;
        }
        face_start.push(face_list.len() as u32);
    }
    Edges {
        ends,
        of_corner,
        face_start,
        face_list,
    }
}

impl Edges {
    fn faces(&self, e: usize) -> &[u32] {
        &self.face_list[self.face_start[e] as usize..self.face_start[e + 1] as usize]
    }
}

/// Per-vertex incidence: the edges and faces around each vertex (CSR).
struct Incidence {
    edge_start: Vec<u32>,
    edges: Vec<u32>,
    face_start: Vec<u32>,
    faces: Vec<u32>,
}

fn incidence(cage: &Cage, edges: &Edges) -> Incidence {
    let n = cage.points.len();
    let csr = |pairs: &mut Vec<(u32, u32)>| {
        pairs.par_sort_unstable();
        let mut start = vec![0u32; n + 1];
        for &(v, _) in pairs.iter() {
            start[v as usize + 1] += 1;
        }
        for v in 0..n {
            start[v + 1] += start[v];
        }
        (start, pairs.iter().map(|p| p.1).collect::<Vec<u32>>())
    };
    let mut edge_pairs: Vec<(u32, u32)> = edges
        .ends
        .iter()
        .enumerate()
        .flat_map(|(e, [a, b])| [(*a, e as u32), (*b, e as u32)])
        .collect();
    let (edge_start, edge_list) = csr(&mut edge_pairs);
    let mut face_pairs: Vec<(u32, u32)> = Vec::with_capacity(cage.indices.len());
    for f in 0..cage.counts.len() {
        let start = cage.starts[f] as usize;
        for c in start..start + cage.counts[f] as usize {
            face_pairs.push((cage.indices[c], f as u32));
        }
    }
    let (face_start, face_list) = csr(&mut face_pairs);
    Incidence {
        edge_start,
        edges: edge_list,
        face_start,
        faces: face_list,
    }
}

impl Incidence {
    fn edges(&self, v: usize) -> &[u32] {
        &self.edges[self.edge_start[v] as usize..self.edge_start[v + 1] as usize]
    }
    fn faces(&self, v: usize) -> &[u32] {
        &self.faces[self.face_start[v] as usize..self.face_start[v + 1] as usize]
    }
}

/// How a vertex moves: by its sharp edges (count and mean sharpness) and its own sharpness.
enum VertexRule {
    Smooth,
    Crease { a: u32, b: u32, sharpness: f32 },
    Corner { sharpness: f32 },
}

fn vertex_rule(
    cage: &Cage,
    edges: &Edges,
    inc: &Incidence,
    v: usize,
    boundary: BoundaryInterpolation,
) -> VertexRule {
    let mut sharp = Vec::new();
    let mut boundary_edges = 0;
    for &e in inc.edges(v) {
        let s = cage.edge_sharpness[e as usize];
        if edges.faces(e as usize).len() != 2 {
            boundary_edges += 1;
        }
        if s > 0.0 {
            let [a, b] = edges.ends[e as usize];
            sharp.push((if a as usize == v { b } else { a }, s));
        }
    }
    let vertex = cage.vertex_sharpness[v];
    let one_face_boundary = boundary_edges > 0
        && inc.faces(v).len() == 1
        && boundary == BoundaryInterpolation::EdgeAndCorner;
    if vertex > 0.0 || sharp.len() > 2 || one_face_boundary || boundary_edges > 2 {
        let mean = if sharp.len() > 2 {
            sharp.iter().map(|s| s.1).sum::<f32>() / sharp.len() as f32
        } else {
            0.0
        };
        let s = if one_face_boundary || boundary_edges > 2 {
            INFINITELY_SHARP
        } else {
            vertex.max(mean)
        };
        return VertexRule::Corner { sharpness: s };
    }
    if sharp.len() == 2 {
        return VertexRule::Crease {
            a: sharp[0].0,
            b: sharp[1].0,
            sharpness: (sharp[0].1 + sharp[1].1) / 2.0,
        };
    }
    VertexRule::Smooth
}

/// The cage's face-varying values of face `f`'s corners, `width` each.
fn corner_values(cage: &Cage, c: usize) -> &[f32] {
    &cage.fvar[c * cage.width..(c + 1) * cage.width]
}

/// One level of refinement of `cage`, whose edges are `edges`; returns the child cage and
/// its edges.
fn refine_once(
    cage: &Cage,
    edges: &Edges,
    scheme: SubdivisionScheme,
    boundary: BoundaryInterpolation,
) -> (Cage, Edges) {
    let inc = incidence(cage, edges);
    let (nv, ne, nf) = (cage.points.len(), edges.ends.len(), cage.counts.len());
    let face_points: Vec<DVec3> = (0..nf)
        .into_par_iter()
        .map(|f| {
            let start = cage.starts[f] as usize;
            let n = cage.counts[f] as usize;
            cage.indices[start..start + n]
                .iter()
                .map(|&i| cage.points[i as usize])
                .sum::<DVec3>()
                / n as f64
        })
        .collect();
    let loop_scheme = scheme == SubdivisionScheme::Loop;
    let bilinear = scheme == SubdivisionScheme::Bilinear;
    // Edge points.
    let edge_points: Vec<DVec3> = (0..ne)
        .into_par_iter()
        .map(|e| {
            let [a, b] = edges.ends[e];
            let (pa, pb) = (cage.points[a as usize], cage.points[b as usize]);
            let mid = (pa + pb) * 0.5;
            let faces = edges.faces(e);
            let s = cage.edge_sharpness[e];
            if bilinear || faces.len() != 2 || s >= 1.0 {
                return mid;
            }
            let smooth = if loop_scheme {
                // 3/8 of each end, 1/8 of each opposite vertex.
                let opposite = |f: u32| {
                    let start = cage.starts[f as usize] as usize;
                    cage.indices[start..start + 3]
                        .iter()
                        .copied()
                        .find(|&i| i != a && i != b)
                        .map_or(mid, |i| cage.points[i as usize])
                };
                (pa + pb) * 0.375 + (opposite(faces[0]) + opposite(faces[1])) * 0.125
            } else {
                (pa + pb + face_points[faces[0] as usize] + face_points[faces[1] as usize]) * 0.25
            };
            smooth.lerp(mid, s as f64)
        })
        .collect();
    // Vertex points.
    let vertex_points: Vec<DVec3> = (0..nv)
        .into_par_iter()
        .map(|v| {
            let p = cage.points[v];
            if bilinear || inc.edges(v).is_empty() {
                return p;
            }
            let smooth = || {
                let n = inc.edges(v).len() as f64;
                let neighbours: DVec3 = inc
                    .edges(v)
                    .iter()
                    .map(|&e| {
                        let [a, b] = edges.ends[e as usize];
                        cage.points[if a as usize == v { b } else { a } as usize]
                    })
                    .sum();
                if loop_scheme {
                    let beta = loop_beta(n);
                    p * (1.0 - n * beta) + neighbours * beta
                } else {
                    let q = inc
                        .faces(v)
                        .iter()
                        .map(|&f| face_points[f as usize])
                        .sum::<DVec3>()
                        / inc.faces(v).len() as f64;
                    let r = (p * n + neighbours) / (2.0 * n); // mean of the edge midpoints
                    (q + r * 2.0 + p * (n - 3.0)) / n
                }
            };
            match vertex_rule(cage, edges, &inc, v, boundary) {
                VertexRule::Smooth => smooth(),
                VertexRule::Crease { a, b, sharpness } => {
                    let crease =
                        (p * 6.0 + cage.points[a as usize] + cage.points[b as usize]) / 8.0;
                    if sharpness >= 1.0 {
                        crease
                    } else {
                        smooth().lerp(crease, sharpness as f64)
                    }
                }
                VertexRule::Corner { sharpness } => {
                    if sharpness >= 1.0 {
                        p
                    } else {
                        smooth().lerp(p, sharpness as f64)
                    }
                }
            }
        })
        .collect();
    // Child topology, sharpness and face-varying values.
    let mut points = vertex_points;
    points.extend(edge_points);
    let first_face_point = points.len() as u32;
    if !loop_scheme {
        points.extend(face_points);
    }
    let w = cage.width;
    let mut counts = Vec::new();
    let mut indices = Vec::new();
    let mut fvar = Vec::new();
    let mut keep = Vec::new();
    let mid = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| 0.5 * (x + y))
            .collect::<Vec<f32>>()
    };
    for f in 0..nf {
        let start = cage.starts[f] as usize;
        let n = cage.counts[f] as usize;
        let corner = |k: usize| start + k % n;
        let edge_point = |k: usize| nv as u32 + edges.of_corner[corner(k)];
        if loop_scheme {
            // (a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca).
            let (v0, v1, v2) = (
                cage.indices[start],
                cage.indices[start + 1],
                cage.indices[start + 2],
            );
            let (e01, e12, e20) = (edge_point(0), edge_point(1), edge_point(2));
            for tri in [
                [v0, e01, e20],
                [e01, v1, e12],
                [e20, e12, v2],
                [e01, e12, e20],
            ] {
                counts.push(3);
                indices.extend(tri);
                keep.push(cage.keep[f]);
            }
            if w > 0 {
                let (c0, c1, c2) = (
                    corner_values(cage, start),
                    corner_values(cage, start + 1),
                    corner_values(cage, start + 2),
                );
                let (m01, m12, m20) = (mid(c0, c1), mid(c1, c2), mid(c2, c0));
                for tri in [
                    [c0, &m01[..], &m20[..]],
                    [&m01[..], c1, &m12[..]],
                    [&m20[..], &m12[..], c2],
                    [&m01[..], &m12[..], &m20[..]],
                ] {
                    for c in tri {
                        fvar.extend_from_slice(c);
                    }
                }
            }
            continue;
        }
        let centre: Vec<f32> = (0..w)
            .map(|k| {
                (0..n)
                    .map(|i| corner_values(cage, start + i)[k])
                    .sum::<f32>()
                    / n as f32
            })
            .collect();
        for i in 0..n {
            // (v_i, e_i, face point, e_{i-1}).
            counts.push(4);
            indices.extend([
                cage.indices[corner(i)],
                edge_point(i),
                first_face_point + f as u32,
                edge_point(i + n - 1),
            ]);
            keep.push(cage.keep[f]);
            if w > 0 {
                let here = corner_values(cage, corner(i));
                let next = corner_values(cage, corner(i + 1));
                let previous = corner_values(cage, corner(i + n - 1));
                fvar.extend_from_slice(here);
                fvar.extend(mid(here, next));
                fvar.extend_from_slice(&centre);
                fvar.extend(mid(previous, here));
            }
        }
    }
    let starts = starts_of(&counts);
    let mut child = Cage {
        points,
        counts,
        starts,
        indices,
        width: w,
        fvar,
        edge_sharpness: Vec::new(),
        vertex_sharpness: cage
            .vertex_sharpness
            .iter()
            .map(|&s| decay(s))
            .chain(std::iter::repeat_n(
                0.0,
                ne + if loop_scheme { 0 } else { nf },
            ))
            .collect(),
        keep,
    };
    // Child edges: the halves of a parent edge inherit its sharpness less one; edges
    // inside a parent face are smooth. Boundary edges stay boundary by topology.
    let mut half_sharpness = std::collections::HashMap::new();
    for e in 0..ne {
        let s = cage.edge_sharpness[e];
        if s > 0.0 && edges.faces(e).len() == 2 {
            let [a, b] = edges.ends[e];
            let m = nv as u32 + e as u32;
            half_sharpness.insert(key(a, m), decay(s));
            half_sharpness.insert(key(m, b), decay(s));
        }
    }
    let child_edges = build_edges(&child);
    child.edge_sharpness = edge_sharpness(&child_edges, &half_sharpness);
    (child, child_edges)
}

/// Each edge's sharpness: infinite on a boundary (or non-manifold) edge, else the value
/// `creases` gives its endpoints' key, else smooth.
fn edge_sharpness(edges: &Edges, creases: &std::collections::HashMap<u64, f32>) -> Vec<f32> {
    edges
        .ends
        .iter()
        .enumerate()
        .map(|(e, [a, b])| {
            if edges.faces(e).len() != 2 {
                INFINITELY_SHARP
            } else {
                creases.get(&key(*a, *b)).copied().unwrap_or(0.0)
            }
        })
        .collect()
}

fn key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    (lo as u64) << 32 | hi as u64
}

fn decay(s: f32) -> f32 {
    if s >= INFINITELY_SHARP {
        s
    } else {
        (s - 1.0).max(0.0)
    }
}

fn starts_of(counts: &[u32]) -> Vec<u32> {
    let mut starts = Vec::with_capacity(counts.len());
    let mut at = 0;
    for &c in counts {
        starts.push(at);
        at += c;
    }
    starts
}

/// Loop's vertex weight β(n) (Loop 1987, with Warren's simplification avoided: the
/// original), used for smooth vertices.
fn loop_beta(n: f64) -> f64 {
    let c = 0.375 + 0.25 * (2.0 * std::f64::consts::PI / n).cos();
    (0.625 - c * c) / n
}

/// Moves every vertex of a refined cage to its limit position.
fn limit_positions(
    cage: &Cage,
    edges: &Edges,
    scheme: SubdivisionScheme,
    boundary: BoundaryInterpolation,
) -> Vec<DVec3> {
    if scheme == SubdivisionScheme::Bilinear {
        return cage.points.clone();
    }
    let inc = incidence(cage, edges);
    (0..cage.points.len())
        .into_par_iter()
        .map(|v| {
            let p = cage.points[v];
            if inc.edges(v).is_empty() {
                return p;
            }
            match vertex_rule(cage, edges, &inc, v, boundary) {
                VertexRule::Corner { .. } => p,
                VertexRule::Crease { a, b, .. } => {
                    (p * 4.0 + cage.points[a as usize] + cage.points[b as usize]) / 6.0
                }
                VertexRule::Smooth => {
                    let n = inc.edges(v).len() as f64;
                    let neighbours: DVec3 = inc
                        .edges(v)
                        .iter()
                        .map(|&e| {
                            let [a, b] = edges.ends[e as usize];
                            cage.points[if a as usize == v { b } else { a } as usize]
                        })
                        .sum();
                    if scheme == SubdivisionScheme::Loop {
                        let chi = 1.0 / (3.0 / (8.0 * loop_beta(n)) + n);
                        p * (1.0 - n * chi) + neighbours * chi
                    } else {
                        // Quads after one level: each face around v adds its diagonal.
                        let diagonals: DVec3 = inc
                            .faces(v)
                            .iter()
                            .map(|&f| {
                                let start = cage.starts[f as usize] as usize;
                                let corners = &cage.indices[start..start + 4];
                                let k = corners.iter().position(|&i| i as usize == v).unwrap_or(0);
                                cage.points[corners[(k + 2) % 4] as usize]
                            })
                            .sum();
                        (p * n * n + neighbours * 4.0 + diagonals) / (n * (n + 5.0))
                    }
                }
            }
        })
        .collect()
}

/// Faces a surface has after `level` levels (for memory estimates and level choice).
pub fn refined_face_count(surface: &SubdivisionSurface, level: u32) -> u64 {
    let first: u64 = match surface.scheme {
        SubdivisionScheme::Loop => surface.face_counts.len() as u64 * 4,
        _ => surface.face_counts.iter().map(|&n| n as u64).sum(),
    };
    if level == 0 {
        surface.face_counts.len() as u64
    } else {
        first * 4u64.pow(level - 1)
    }
}

/// The refined surface as a triangle mesh named `name` with material `material`.
pub fn refine(surface: &SubdivisionSurface, level: u32, name: &str, material: u32) -> Mesh {
    let width = 2 * surface.uvs.is_some() as usize + 4 * surface.colors.is_some() as usize;
    let mut fvar = Vec::with_capacity(surface.face_indices.len() * width);
    for c in 0..surface.face_indices.len() {
        if let Some(uv) = &surface.uvs {
            fvar.extend(uv[c].to_array());
        }
        if let Some(col) = &surface.colors {
            fvar.extend(col[c].to_array());
        }
    }
    let mut cage = Cage {
        points: surface.points.iter().map(|p| p.as_dvec3()).collect(),
        starts: starts_of(&surface.face_counts),
        counts: surface.face_counts.clone(),
        indices: surface.face_indices.clone(),
        width,
        fvar,
        edge_sharpness: Vec::new(),
        vertex_sharpness: vec![0.0; surface.points.len()],
        keep: surface
            .keep
            .clone()
            .unwrap_or_else(|| vec![true; surface.face_counts.len()]),
    };
    for &(v, s) in &surface.corners {
        if let Some(x) = cage.vertex_sharpness.get_mut(v as usize) {
            *x = x.max(s);
        }
    }
    let mut edges = build_edges(&cage);
    let creases: std::collections::HashMap<u64, f32> = surface
        .creases
        .iter()
        .map(|&([a, b], s)| (key(a, b), s))
        .collect();
    cage.edge_sharpness = edge_sharpness(&edges, &creases);
    for _ in 0..level {
        (cage, edges) = refine_once(&cage, &edges, surface.scheme, surface.boundary);
    }
    let limit = if level > 0 {
        limit_positions(&cage, &edges, surface.scheme, surface.boundary)
    } else {
        cage.points.clone()
    };
    triangulate(&cage, &edges, &limit, surface, name, material)
}

/// The kept faces as triangles, with normals that stay apart across sharp edges and
/// vertices welded where position, normal and face-varying values agree.
fn triangulate(
    cage: &Cage,
    edges: &Edges,
    points: &[DVec3],
    surface: &SubdivisionSurface,
    name: &str,
    material: u32,
) -> Mesh {
    let corners = cage.indices.len();
    // Face area vectors (Newell).
    let face_normal: Vec<DVec3> = (0..cage.counts.len())
        .map(|f| {
            let start = cage.starts[f] as usize;
            let n = cage.counts[f] as usize;
            let mut sum = DVec3::ZERO;
            for k in 0..n {
                let a = points[cage.indices[start + k] as usize];
                let b = points[cage.indices[start + (k + 1) % n] as usize];
                sum += a.cross(b);
            }
            sum * 0.5
        })
        .collect();
    let mut face_of_corner = vec![0u32; corners];
    for f in 0..cage.counts.len() {
        let start = cage.starts[f] as usize;
        face_of_corner[start..start + cage.counts[f] as usize].fill(f as u32);
    }
    // Smoothing groups: corners at one vertex joined across every smooth edge.
    let mut parent: Vec<u32> = (0..corners as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    // The corner of each edge's faces at each end: corner c starts edge of_corner[c].
    let mut starts_of_edge: Vec<Vec<u32>> = vec![Vec::new(); edges.ends.len()];
    for c in 0..corners {
        starts_of_edge[edges.of_corner[c] as usize].push(c as u32);
    }
    for (e, users) in starts_of_edge.iter().enumerate() {
        if users.len() != 2 || cage.edge_sharpness[e] > 0.0 {
            continue;
        }
        let (c, d) = (users[0] as usize, users[1] as usize);
        // A bilinear surface is its faceted cage: shading joins only coplanar faces.
        if surface.scheme == SubdivisionScheme::Bilinear {
            let (a, b) = (
                face_normal[face_of_corner[c] as usize].normalize_or_zero(),
                face_normal[face_of_corner[d] as usize].normalize_or_zero(),
            );
            if a.dot(b) < 1.0 - 1e-9 {
                continue;
            }
        }
        let next = |c: usize| next_corner(cage, face_of_corner[c] as usize, c);
        // c runs a→b in its face, d runs b→a in the other: c ~ next(d), next(c) ~ d.
        for (x, y) in [(c, next(d)), (next(c), d)] {
            let (rx, ry) = (find(&mut parent, x as u32), find(&mut parent, y as u32));
            if rx != ry {
                parent[rx as usize] = ry;
            }
        }
    }
    let mut group_normal = vec![DVec3::ZERO; corners];
    for c in 0..corners {
        let root = find(&mut parent, c as u32);
        group_normal[root as usize] += face_normal[face_of_corner[c] as usize];
    }
    // Weld corners of kept faces: one vertex per smoothing group (all of whose corners sit
    // at one point), split further only where face-varying values differ (a UV seam).
    let w = cage.width;
    let values = |c: u32| &cage.fvar[c as usize * w..(c as usize + 1) * w];
    let bits = |c: u32| values(c).iter().map(|x| x.to_bits());
    let mut vertex_of_group = vec![u32::MAX; corners];
    let mut seams: std::collections::HashMap<(u32, Vec<u32>), u32> = Default::default();
    let mut vertex_of_corner = vec![u32::MAX; corners];
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut fv_out: Vec<u32> = Vec::new();
    for f in 0..cage.counts.len() {
        if !cage.keep[f] {
            continue;
        }
        let start = cage.starts[f] as usize;
        for c in (start..start + cage.counts[f] as usize).map(|c| c as u32) {
            let g = find(&mut parent, c);
            let first = vertex_of_group[g as usize];
            let vertex = if first != u32::MAX && bits(fv_out[first as usize]).eq(bits(c)) {
                first
            } else if first != u32::MAX && seams.contains_key(&(g, bits(c).collect())) {
                seams[&(g, bits(c).collect())]
            } else {
                let v = positions.len() as u32;
                positions.push(points[cage.indices[c as usize] as usize].as_vec3());
                normals.push(
                    group_normal[g as usize]
                        .try_normalize()
                        .unwrap_or(DVec3::Z)
                        .as_vec3(),
                );
                fv_out.push(c);
                if first == u32::MAX {
                    vertex_of_group[g as usize] = v;
                } else {
                    seams.insert((g, bits(c).collect()), v);
                }
                v
            };
            vertex_of_corner[c as usize] = vertex;
        }
    }
    let mut triangles = Vec::new();
    for f in 0..cage.counts.len() {
        if !cage.keep[f] {
            continue;
        }
        let start = cage.starts[f] as usize;
        let n = cage.counts[f] as usize;
        for k in 1..n - 1 {
            triangles.push([
                vertex_of_corner[start],
                vertex_of_corner[start + k],
                vertex_of_corner[start + k + 1],
            ]);
        }
    }
    let value = |c: u32, offset: usize, count: usize| -> &[f32] {
        &cage.fvar[c as usize * w + offset..c as usize * w + offset + count]
    };
    let uvs = surface.uvs.as_ref().map(|_| {
        fv_out
            .iter()
            .map(|&c| Vec2::from_slice(value(c, 0, 2)))
            .collect()
    });
    let colour_offset = 2 * surface.uvs.is_some() as usize;
    let colors = surface.colors.as_ref().map(|_| {
        fv_out
            .iter()
            .map(|&c| Vec4::from_slice(value(c, colour_offset, 4)))
            .collect()
    });
    Mesh {
        name: name.to_string(),
        positions,
        normals: Some(normals),
        tangents: None,
        uvs: [uvs, None],
        colors,
        triangles,
        material,
        deformation: None,
    }
}

/// The level that brings the cage's mean edge, seen `pixels_per_unit` pixels a world unit
/// away, to about `target_pixels` on screen (each level halves edges), at most `MAX_LEVEL`,
/// at least 1 (a subdivision surface is never its cage).
pub fn level_for(mean_edge: f64, pixels_per_unit: f64, target_pixels: f64) -> u32 {
    let pixels = mean_edge * pixels_per_unit;
    if !(pixels.is_finite() && pixels > target_pixels) {
        return 1;
    }
    ((pixels / target_pixels).log2().ceil() as u32).clamp(1, MAX_LEVEL)
}

/// Mean length of the cage's edges (each edge counted once per face using it).
pub fn mean_edge_length(surface: &SubdivisionSurface) -> f64 {
    let mut sum = 0.0;
    let mut count = 0usize;
    let mut start = 0usize;
    for &n in &surface.face_counts {
        let n = n as usize;
        for k in 0..n {
            let a = surface.points[surface.face_indices[start + k] as usize];
            let b = surface.points[surface.face_indices[start + (k + 1) % n] as usize];
            sum += a.distance(b) as f64;
            count += 1;
        }
        start += n;
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn cube(creases: Vec<([u32; 2], f32)>) -> SubdivisionSurface {
        let points = (0..8)
            .map(|i| {
                Vec3::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32) * 2.0 - 1.0
            })
            .collect();
        SubdivisionSurface {
            point_keys: Vec::new(),
            mesh: 0,
            scheme: SubdivisionScheme::CatmullClark,
            boundary: BoundaryInterpolation::EdgeAndCorner,
            points,
            face_counts: vec![4; 6],
            #[rustfmt::skip]
            face_indices: vec![
                0, 2, 3, 1,  4, 5, 7, 6,  0, 1, 5, 4,  2, 6, 7, 3,  0, 4, 6, 2,  1, 3, 7, 5,
            ],
            creases,
            corners: vec![],
            uvs: None,
            colors: None,
            keep: None,
        }
    }

    fn has_point(mesh: &Mesh, p: Vec3) -> bool {
        mesh.positions.iter().any(|q| q.distance(p) < 1e-5)
    }

    /// Limit points of the Catmull-Clark cube (corners at ±1) worked out by hand: one
    /// level moves a corner (valence 3) to (Q + 2R)/3 = 5/9 (1, 1, 1) and makes the edge
    /// points (0, 3/4, 3/4) and the face points (1, 0, 0); the limit mask
    /// (n² v + 4 Σ e + Σ f) / (n (n + 5)) then puts the corner at (1/2, 1/2, 1/2) and a face
    /// centre (valence 4) at (68/81, 0, 0). Both are vertices at every level.
    #[test]
    fn catmull_clark_cube_reaches_its_limit_points() {
        for level in 1..=3 {
            let mesh = refine(&cube(vec![]), level, "cube", 0);
            for sx in [-1.0, 1.0] {
                for sy in [-1.0, 1.0] {
                    for sz in [-1.0, 1.0] {
                        let corner = Vec3::new(sx, sy, sz) * 0.5;
                        assert!(has_point(&mesh, corner), "level {level}: no {corner}");
                    }
                }
            }
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                for sign in [-1.0, 1.0] {
                    let centre = axis * sign * (68.0 / 81.0);
                    assert!(has_point(&mesh, centre), "level {level}: no {centre}");
                }
            }
            assert_eq!(
                mesh.triangles.len() as u64,
                2 * refined_face_count(&cube(vec![]), level)
            );
        }
    }

    /// Creases on the four edges parallel to y: a corner has one sharp edge (a dart, the
    /// smooth rule: 5/9 (1, 1, 1) after one level), the edge's midpoint is sharp (1, 0, 1),
    /// and the crease's B-spline limit (a + 4 m + b)/6 puts it at 23/27 (1, 0, 1).
    #[test]
    fn creased_cube_reaches_its_crease_limit() {
        let vertical: Vec<([u32; 2], f32)> = [[0, 2], [1, 3], [4, 6], [5, 7]]
            .iter()
            .map(|&e| (e, 10.0))
            .collect();
        let mesh = refine(&cube(vertical), 2, "cube", 0);
        let m = 23.0 / 27.0;
        for (x, z) in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
            assert!(
                has_point(&mesh, Vec3::new(x * m, 0.0, z * m)),
                "no crease limit at ({x}, {z})"
            );
        }
        // Normals stay apart across the crease: two vertices at each crease point.
        let p = Vec3::new(m, 0.0, m);
        let at_crease = mesh
            .positions
            .iter()
            .filter(|q| q.distance(p) < 1e-5)
            .count();
        assert_eq!(at_crease, 2);
    }

    #[test]
    fn infinitely_sharp_creases_keep_the_cube_edges() {
        // All 12 edges infinitely sharp: the limit is the cube itself.
        let edges: Vec<([u32; 2], f32)> = [
            [0, 1],
            [2, 3],
            [4, 5],
            [6, 7],
            [0, 2],
            [1, 3],
            [4, 6],
            [5, 7],
            [0, 4],
            [1, 5],
            [2, 6],
            [3, 7],
        ]
        .iter()
        .map(|&e| (e, 10.0))
        .collect();
        let mesh = refine(&cube(edges), 3, "cube", 0);
        for p in &mesh.positions {
            assert!(
                (p.abs().max_element() - 1.0).abs() < 1e-5,
                "{p} is off the cube"
            );
        }
    }
}
