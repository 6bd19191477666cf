//! Step 1: dynamic 3D Gaussians fitted to the sequence (model, losses with their
//! gradients, optimiser, initialisation, schedule, model selection).
