"""physinfer's hanging-cloth plugin: the Bouman et al. hanging-fabric phenomenon and evaluation."""
