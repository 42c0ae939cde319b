// rosrust's message macros read the definitions named by ROSRUST_MSG_PATH (.cargo/config.toml).
fn main() {
    println!("cargo:rerun-if-env-changed=ROSRUST_MSG_PATH");
    println!("cargo:rerun-if-changed=msgs");
}
