fn main() -> std::process::ExitCode {
    voxtrace::cli::main()
}
