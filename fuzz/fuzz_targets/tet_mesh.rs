//! The input as a tet mesh's arrays (what every mesh reader hands the core): a count byte, then
//! f64 coordinates and i64 indices. TetMesh::from_arrays must accept or refuse, never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use palpate_core::mesh::TetMesh;

fuzz_target!(|data: &[u8]| {
    if data.is_empty() {
        return;
    }
    let n = (data[0] as usize % 16) + 1;
    let rest = &data[1..];
    let f = |i: usize| rest.get(8 * i..8 * i + 8).map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]))).unwrap_or(0.0);
    let points: Vec<[f64; 3]> = (0..n).map(|i| [f(3 * i), f(3 * i + 1), f(3 * i + 2)]).collect();
    let idx = rest.get(24 * n..).unwrap_or(&[]);
    // Indices as small bytes mostly (so valid meshes occur), the high bit making them huge/negative.
    let tets: Vec<[i64; 4]> = idx
        .chunks_exact(4)
        .map(|c| std::array::from_fn(|k| if c[k] & 0x80 != 0 { (c[k] as i8 as i64) << 40 } else { (c[k] % (n as u8 + 1)) as i64 }))
        .collect();
    if let Ok((mesh, _)) = TetMesh::from_arrays(&points, &tets) {
        let _ = mesh.volume();
        let _ = mesh.boundary_faces();
        let _ = mesh.min_dihedral_deg();
    }
});
