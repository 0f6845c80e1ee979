int main(int argc, char** argv) {
  if (argc > 1) return 2;
  return 0;
}
