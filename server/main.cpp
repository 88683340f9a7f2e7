// terrabound: the command-line entry point (subcommands dispatch to their modules).
int main() { return 0; }
