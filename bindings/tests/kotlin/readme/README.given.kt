// Given to the ```kotlin example of README.md (bindings/tests/kotlin/readme_examples.py prepends it): the
// camera's buffers the example takes from the app around it. Sizes only; the example is compiled, not run.
val bgra = ByteArray(1920 * 1440 * 4)   // BGRA8 colour, 1920 × 1440
val depth16 = ByteArray(640 * 480 * 2)  // DEPTH16 depth, 640 × 480
