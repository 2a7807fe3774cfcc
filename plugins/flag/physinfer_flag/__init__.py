"""physinfer's flag plugin: cloth physics, pyrender renderer, SDN embedder, FlagSim."""
