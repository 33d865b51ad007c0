// Placeholder until the CLI lands in this file.
int main() { return 0; }
