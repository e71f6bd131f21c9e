use voxtrace::geometry::Ellipsoid;
use voxtrace::index::VoxelHashGrid;
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let scene = voxtrace::scene::parse(std::fs::read(path).unwrap()).unwrap();
    let shapes: Vec<Ellipsoid<f32>> = scene.spheres.iter().map(Ellipsoid::from_sphere).collect();
    let grid = VoxelHashGrid::new(&shapes);
    for l in grid.levels() { println!("{l:?}"); }
    println!("bytes/sphere {}", grid.bytes() as f64 / shapes.len() as f64);
}
