"""The patch layout: cutting, clustering, contacts, and the reconstruction of smooth values from patch values."""
