//! Writes the example characters into `assets/characters/` (or the folder given as the first
//! argument): `cargo run --example make_characters`. The committed files must equal this
//! output; a unit test in `src/character/examples.rs` checks it.

fn main() -> anyhow::Result<()> {
    let dir = std::env::args_os()
        .nth(1)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("assets/characters")
        });
    std::fs::create_dir_all(&dir)?;
    for path in leman::character::examples::write_all(&dir)? {
        println!("wrote {}", path.display());
    }
    Ok(())
}
