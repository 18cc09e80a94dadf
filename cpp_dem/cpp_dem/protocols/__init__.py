"""What is done to a scene: box preparation to a porosity or stress (`prep`), the triaxial test
(`triaxial`), the geogrid pull-out (`pullout`), prestress of a grid's members (`prestress`) and
preparation and control of periodic cells (`periodic`)."""
